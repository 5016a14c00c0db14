"""Report of `teleop fidelity --reference cosserat`: the comparisons of `harness.studies.fidelity_reference`,
the paper scenario's closed loop on each plant, the Markdown tables, the JSON rows and the figure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from harness.studies.fidelity_reference import modal_comparison, static_comparison
from harness.studies.figures import md_table, printer, pyplot, run_paper, save, save_figure

METRICS_MM = {"e2_rms_mm": "e2_rms", "e2_max_mm": "e2_max", "beta_min": "beta_min",
              "range_violation_mm": "range_violation"}  # column: metric (m, shown in mm when "_mm")


def closed_loop_rows(N: int = 8, duration: float = 20.0, seed: int = 0, say=lambda s: None) -> list[dict]:
    """The paper scenario (servo) on each plant: analytic, MuJoCo chain CC on / off at N, and the Cosserat
    rod when the harness has `plant.kind = "cosserat"` (else a row saying it is missing)."""
    from harness.config.scenario import PLANTS

    cases = [("analytic CC (RK4)", ["plant.kind=analytic"]),
             (f"MuJoCo chain N = {N}, CC on", [f"plant.segments={N}", "plant.enforce_cc=true"]),
             (f"MuJoCo chain N = {N}, CC off (default)", [f"plant.segments={N}", "plant.enforce_cc=false"])]
    if "cosserat" in PLANTS:
        cases.append(("Cosserat rod", ["plant.kind=cosserat"]))
    rows = []
    for name, sets in cases:
        tr, m = run_paper([*sets, f"duration={duration}", f"seed={seed}"])
        status = tr.status if tr.status == "ok" else f"{tr.status}: {tr.message}"
        values = {c: (1e3 if c.endswith("_mm") else 1) * m.get(k, np.nan) for c, k in METRICS_MM.items()}
        rows.append({"plant": name, "status": status, **values})
        say(f"closed loop {name}: {rows[-1]['status']}")
    if "cosserat" not in PLANTS:
        rows.append({"plant": "Cosserat rod", "status": "not available: plant.kind = cosserat is not in this "
                     "build", **dict.fromkeys(METRICS_MM, np.nan)})
    return rows


def _md(rows: list[dict], cols: dict[str, str]) -> str:
    def f(v):
        if isinstance(v, bool):
            return "on" if v else "off"
        return f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v)

    cells = [[f(r[c]) for c in cols] for r in rows]
    return "\n".join(md_table(list(cols.values()), cells, ["---"] * len(cols)))


def plot_reference(static_rows, modal_rows, path) -> Path:
    """Static tip error vs the rod and first-mode frequency vs N (CC on / off, analytic and rod lines)."""
    fig, (a, b) = pyplot().subplots(1, 2, figsize=(9.6, 3.8))
    for cc, st in ((True, "s-"), (False, "o-")):
        for ax, rows, key in ((a, static_rows, "tip_err_mm"), (b, modal_rows, "f1_hz")):
            rs = [r for r in rows if r["model"] == "MuJoCo chain" and r["enforce_cc"] == cc]
            ax.semilogx([r["N"] for r in rs], [r[key] for r in rs], st, base=2,
                        label=f"MuJoCo chain, CC {'on' if cc else 'off'}")
    cc_static_err = next(r["tip_err_mm"] for r in static_rows if r["model"] == "analytic CC")
    a.axhline(cc_static_err, color="k", ls="--", lw=0.8, label="analytic CC")
    for r in modal_rows:
        if r["model"] != "MuJoCo chain":
            b.axhline(r["f1_hz"], ls="--" if r["model"] == "analytic CC" else ":", color="k", lw=0.8,
                      label=r["model"])
    a.set(ylabel="max static tip error vs rod (mm)")
    a.set_title("statics (gravity, 1 N tip load)", fontsize=9)
    b.set(ylabel="first bending mode (Hz)")
    b.set_title("released 1 N tip deflection", fontsize=9)
    for ax in (a, b):
        ax.set_xlabel("segments per section N")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def main_reference(segments, out, progress: bool = True, seed: int = 0, loop_duration: float = 20.0) -> int:
    """`teleop fidelity --reference cosserat`: statics, small motion and closed loop of the analytic CC
    model and the MuJoCo chain (CC on / off, each N) against the Cosserat rod; writes
    fidelity_reference.md, fidelity_reference.json and fidelity_reference.png into `out`."""
    out, say = Path(out), printer(progress)
    Ns = tuple(int(n) for n in segments)
    st = static_comparison(Ns=Ns, say=say)
    mo = modal_comparison(Ns=Ns, say=say)
    cl = closed_loop_rows(8, loop_duration, seed, say=say)
    text = "\n\n".join([
        "Statics: max over 5 commanded shapes x 2 loads (gravity; + 1 N tip force along +X)\n\n"
        + _md(st, {"model": "model", "N": "N", "enforce_cc": "CC", "tip_err_mm": "tip vs rod (mm)",
                   "cc_dev_mm": "own departure from CC (mm)", "worst": "worst case"}),
        "Small motion: straight arm released from a 1 N tip deflection (default material damping)\n\n"
        + _md(mo, {"model": "model", "N": "N", "enforce_cc": "CC", "f1_hz": "f1 (Hz)", "zeta1": "zeta1"}),
        f"Closed loop: paper scenario, servo, {loop_duration:g} s, seed {seed}\n\n"
        + _md(cl, {"plant": "plant", "status": "status", "e2_rms_mm": "e2 RMS (mm)",
                   "e2_max_mm": "e2 max (mm)", "beta_min": "beta min",
                   "range_violation_mm": "range violation (mm)"})])
    save(out / "fidelity_reference.md", text + "\n")
    save(out / "fidelity_reference.json", json.dumps({"static": st, "modal": mo, "closed_loop": cl}, indent=1,
                                                     default=float))
    plot_reference(st, mo, out / "fidelity_reference.png")
    print(text)
    print(f"outputs in {out}/: fidelity_reference.md, fidelity_reference.json, fidelity_reference.png")
    return 0
