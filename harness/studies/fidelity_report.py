"""Report of the fidelity-vs-reference study (`teleop fidelity --reference cosserat`): the closed loop
of the paper scenario on each plant, the markdown tables, the figure and the files written.  The
comparisons themselves (statics, small motion, worst cases) are in `harness.studies.fidelity_reference`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.studies.fidelity_reference import modal_comparison, static_comparison
from harness.studies.figures import save_figure


# ------------------------------------------------------------------------------------------------
# closed loop and the report
# ------------------------------------------------------------------------------------------------
def closed_loop_rows(N: int = 8, duration: float = 20.0, seed: int = 0, say=lambda s: None) -> list[dict]:
    """The paper scenario (servo) on each plant: analytic, MuJoCo chain CC on / off at N, and the
    Cosserat rod when the harness has ``plant.kind = "cosserat"`` (else a row saying it is missing)."""
    from harness.config.load import load_scenario
    from harness.config.scenario import PLANTS
    from harness.loop import simulate
    from harness.loop.metrics import compute_metrics

    cases = [("analytic CC (RK4)", ["plant.kind=analytic"]),
             (f"MuJoCo chain N = {N}, CC on", [f"plant.segments={N}", "plant.enforce_cc=true"]),
             (f"MuJoCo chain N = {N}, CC off (default)", [f"plant.segments={N}", "plant.enforce_cc=false"])]
    if "cosserat" in PLANTS:
        cases.append(("Cosserat rod", ["plant.kind=cosserat"]))
    rows = []
    for name, sets in cases:
        scn = load_scenario(None, [*sets, f"duration={duration}", f"seed={seed}"])
        tr = simulate(scn)
        m = compute_metrics(tr, scn)
        status = tr.status if tr.status == "ok" else f"{tr.status}: {tr.message}"
        rows.append({"plant": name, "status": status,
                     "e2_rms_mm": 1e3 * m.get("e2_rms", np.nan), "e2_max_mm": 1e3 * m.get("e2_max", np.nan),
                     "beta_min": m.get("beta_min", np.nan),
                     "range_violation_mm": 1e3 * m.get("range_violation", np.nan)})
        say(f"closed loop {name}: {rows[-1]['status']}")
    if "cosserat" not in PLANTS:
        rows.append({"plant": "Cosserat rod", "status": "not available: plant.kind = cosserat is not in this "
                     "build", "e2_rms_mm": np.nan, "e2_max_mm": np.nan, "beta_min": np.nan,
                     "range_violation_mm": np.nan})
    return rows


def _md(rows: list[dict], cols: dict[str, str]) -> str:
    def f(v):
        if isinstance(v, bool):
            return "on" if v else "off"
        if isinstance(v, (float, np.floating)):
            return f"{v:.4g}"
        return str(v)

    head = "| " + " | ".join(cols.values()) + " |"
    return "\n".join([head, "|" + "---|" * len(cols)] + ["| " + " | ".join(f(r[c]) for c in cols) + " |"
                                                        for r in rows])


def plot_reference(static_rows, modal_rows, path) -> Path:
    """Static tip error vs the rod and first-mode frequency vs N (CC on / off, analytic and rod lines)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(9.6, 3.8))
    for cc, st in ((True, "s-"), (False, "o-")):
        rs = [r for r in static_rows if r["model"] == "MuJoCo chain" and r["enforce_cc"] == cc]
        a.semilogx([r["N"] for r in rs], [r["tip_err_mm"] for r in rs], st, base=2,
                   label=f"MuJoCo chain, CC {'on' if cc else 'off'}")
        rs = [r for r in modal_rows if r["model"] == "MuJoCo chain" and r["enforce_cc"] == cc]
        b.semilogx([r["N"] for r in rs], [r["f1_hz"] for r in rs], st, base=2,
                   label=f"MuJoCo chain, CC {'on' if cc else 'off'}")
    cc_static_err = next(r["tip_err_mm"] for r in static_rows if r["model"] == "analytic CC")
    a.axhline(cc_static_err, color="k", ls="--", lw=0.8, label="analytic CC")
    for r in modal_rows:
        if r["model"] != "MuJoCo chain":
            b.axhline(r["f1_hz"], ls="--" if r["model"] == "analytic CC" else ":", color="k", lw=0.8,
                      label=r["model"])
    a.set_xlabel("segments per section N")
    a.set_ylabel("max static tip error vs rod (mm)")
    a.set_title("statics (gravity, 1 N tip load)", fontsize=9)
    b.set_xlabel("segments per section N")
    b.set_ylabel("first bending mode (Hz)")
    b.set_title("released 1 N tip deflection", fontsize=9)
    for ax in (a, b):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def main_reference(segments, out, progress: bool = True, seed: int = 0, loop_duration: float = 20.0) -> int:
    """`teleop fidelity --reference cosserat`: statics, small motion and closed loop of the analytic
    CC model and the MuJoCo chain (CC on / off, each N) against the Cosserat rod; writes
    fidelity_reference.md, fidelity_reference.json and fidelity_reference.png into `out`."""
    import json
    import sys

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = (lambda msg: print(msg, file=sys.stderr, flush=True)) if progress else (lambda msg: None)
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
    (out / "fidelity_reference.md").write_text(text + "\n")
    (out / "fidelity_reference.json").write_text(json.dumps({"static": st, "modal": mo, "closed_loop": cl},
                                                            indent=1, default=float))
    plot_reference(st, mo, out / "fidelity_reference.png")
    print(text)
    print(f"outputs in {out}/: fidelity_reference.md, fidelity_reference.json, fidelity_reference.png")
    return 0


__all__ = ["closed_loop_rows", "main_reference", "plot_reference"]
