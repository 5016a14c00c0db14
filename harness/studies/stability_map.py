"""Gains x damping stability map: survival time of the paper scenario on a plant, over a grid of the
null-space gain k_n (eq. 27-28) and the rod's bending viscosity eta_b (``plant.bending_viscosity``,
N m^2 s, the same in every section; the chain's hinge damping is eta_b / h).

`stability_map(kns, etas, overrides)` runs ``duration`` s of the paper scenario per cell (the other
fields from ``overrides``, e.g. ``plant.actuation=torque``, ``plant.enforce_cc=false``) and returns
rows {kn, eta_b, status, t_end, e2_rms}; `plot_stability_map` draws the survival time as a heatmap.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.studies.figures import save_figure


def stability_map(kns, etas, overrides=(), duration: float = 3.0, say=lambda s: None) -> list[dict]:
    """Rows over the k_n x eta_b grid: status, t_end (s, time reached), e2_rms (m, nan if diverged or
    shorter than the transient; the transient is set to duration / 2)."""
    from harness.config.load import load_scenario
    from harness.loop import simulate
    from harness.loop.metrics import compute_metrics

    rows = []
    for kn in kns:
        for eta in etas:
            sets = list(overrides) + [f"duration={duration}", f"transient={duration / 2}",
                                      f"gains.kn={kn}", f"plant.bending_viscosity=[{eta},{eta},{eta}]"]
            scn = load_scenario(None, sets)
            tr = simulate(scn)
            e2 = compute_metrics(tr, scn).get("e2_rms", np.nan)
            t_end = float(tr.t[-1]) + float(tr.t[1] - tr.t[0]) if len(tr.t) > 1 else 0.0
            rows.append({"kn": float(kn), "eta_b": float(eta), "status": tr.status,
                         "t_end": min(t_end, duration), "message": tr.message,
                         "e2_rms": float(e2)})
            say(f"kn = {kn:g}, eta_b = {eta:g}: {tr.status} at {rows[-1]['t_end']:.3f} s")
    return rows


def grid_lines(rows: list[dict], text) -> list[str]:
    """Markdown table lines of a k_n x eta_b grid: one row per k_n, one column per eta_b, each cell
    `text(row)` of the grid point's row."""
    kns = sorted({r["kn"] for r in rows})
    etas = sorted({r["eta_b"] for r in rows})
    cell = {(r["kn"], r["eta_b"]): r for r in rows}
    lines = ["| k_n \\ eta_b (N m^2 s) | " + " | ".join(f"{e:g}" for e in etas) + " |",
             "|---:|" + "---:|" * len(etas)]
    for kn in kns:
        lines.append(f"| {kn:g} | " + " | ".join(text(cell[kn, e]) for e in etas) + " |")
    return lines


def stability_markdown(rows: list[dict], duration: float) -> str:
    lines = grid_lines(rows, lambda r: f"ok, {r['e2_rms'] * 1e3:.2f} mm" if r["status"] == "ok"
                       else f"{r['t_end']:.3f} s")
    lines.append("")
    lines.append(f"cells: 'ok, e2 RMS' if the {duration:g} s run finished, else the time it diverged")
    return "\n".join(lines)


def plot_stability_map(maps: dict[str, list[dict]], duration: float, path) -> Path:
    """One heatmap of survival time per named map (e.g. 'chain, servo'), log axes of k_n and eta_b."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(maps), figsize=(4.2 * len(maps), 3.6), squeeze=False)
    for ax, (name, rows) in zip(axes[0], maps.items(), strict=True):
        kns = sorted({r["kn"] for r in rows})
        etas = sorted({r["eta_b"] for r in rows})
        cell = {(r["kn"], r["eta_b"]): r for r in rows}
        Z = np.array([[cell[k, e]["t_end"] for e in etas] for k in kns])
        im = ax.imshow(Z, origin="lower", cmap="viridis", vmin=0, vmax=duration, aspect="auto")
        ax.set_xticks(range(len(etas)), [f"{e:g}" for e in etas])
        ax.set_yticks(range(len(kns)), [f"{k:g}" for k in kns])
        ax.set_xlabel("eta_b (N m^2 s)")
        ax.set_ylabel("k_n")
        ax.set_title(name, fontsize=9)
        for i in range(len(kns)):
            for j in range(len(etas)):
                r = cell[kns[i], etas[j]]
                ax.text(j, i, "ok" if r["status"] == "ok" else f"{r['t_end']:.2f}", ha="center",
                        va="center", fontsize=7, color="w" if Z[i, j] < 0.6 * duration else "k")
    fig.colorbar(im, ax=axes[0].tolist(), label="survival time (s)")
    return save_figure(fig, path)


MAPS = {
    "chain CC off, servo": ["plant.enforce_cc=false", "plant.actuation=servo"],
    "chain CC off, torque": ["plant.enforce_cc=false", "plant.actuation=torque"],
    "chain CC off, torque, no noise": ["plant.enforce_cc=false", "plant.actuation=torque", "snr_db=none"],
    "chain CC on, torque": ["plant.enforce_cc=true", "plant.actuation=torque"],
}
KNS = (1.0, 10.0, 30.0, 100.0, 300.0)
ETAS = (0.0, 0.001, 0.01, 0.1, 1.0)


def main(out="runs/stability_map", duration: float = 3.0) -> int:
    """``teleop stability-map [--out OUT] [--duration S]``: the stability maps (MAPS over KNS x ETAS),
    stability_map.md and stability_map.png in OUT."""
    import sys

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    maps, text = {}, []
    for name, ov in MAPS.items():
        say = lambda s, n=name: print(n, s, file=sys.stderr)  # noqa: E731
        maps[name] = stability_map(KNS, ETAS, ov, duration, say=say)
        text.append(f"{name}\n\n" + stability_markdown(maps[name], duration))
    (out / "stability_map.md").write_text("\n\n".join(text) + "\n")
    plot_stability_map(maps, duration, out / "stability_map.png")
    print("\n\n".join(text))
    return 0


__all__ = ["MAPS", "main", "plot_stability_map", "stability_map", "stability_markdown"]
