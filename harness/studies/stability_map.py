"""Gains x damping stability map (`teleop stability-map`): survival time of the paper scenario over the
null-space gain k_n (27-28) x the bending viscosity eta_b (N m^2 s, every section), for the plants of MAPS."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from harness.studies.figures import md_table, printer, pyplot, run_paper, save, save_figure
from harness.studies.stability_report import radius_along

MAPS = {
    "chain CC off, servo": ["plant.enforce_cc=false", "plant.actuation=servo"],
    "chain CC off, torque": ["plant.enforce_cc=false", "plant.actuation=torque"],
    "chain CC off, torque, no noise": ["plant.enforce_cc=false", "plant.actuation=torque", "snr_db=none"],
    "chain CC on, torque": ["plant.enforce_cc=true", "plant.actuation=torque"],
}
KNS = (1.0, 10.0, 30.0, 100.0, 300.0)
ETAS = (0.0, 0.001, 0.01, 0.1, 1.0)


def stability_map(kns, etas, overrides=(), duration: float = 3.0, say=lambda s: None) -> list[dict]:
    """Rows {kn, eta_b, status, t_end (s, time reached), message, e2_rms (m; nan if diverged or shorter
    than the transient, duration / 2)} over the k_n x eta_b grid, the other fields from `overrides`."""
    rows = []
    for kn, eta in itertools.product(kns, etas):
        tr, m = run_paper([*overrides, f"duration={duration}", f"transient={duration / 2}",
                           f"gains.kn={kn}", f"plant.bending_viscosity=[{eta},{eta},{eta}]"])
        t_end = float(tr.t[-1]) + float(tr.t[1] - tr.t[0]) if len(tr.t) > 1 else 0.0
        rows.append({"kn": float(kn), "eta_b": float(eta), "status": tr.status,
                     "t_end": min(t_end, duration), "message": tr.message,
                     "e2_rms": float(m.get("e2_rms", np.nan))})
        say(f"kn = {kn:g}, eta_b = {eta:g}: {tr.status} at {rows[-1]['t_end']:.3f} s")
    return rows


def _grid(rows: list[dict]) -> tuple[list, list, dict]:
    """(sorted k_n, sorted eta_b, {(k_n, eta_b): row})."""
    return (sorted({r["kn"] for r in rows}), sorted({r["eta_b"] for r in rows}),
            {(r["kn"], r["eta_b"]): r for r in rows})


def grid_lines(rows: list[dict], text) -> list[str]:
    """Markdown table lines of a k_n x eta_b grid: one row per k_n, one column per eta_b, each cell
    `text(row)` of the grid point's row."""
    kns, etas, cell = _grid(rows)
    return md_table(["k_n \\ eta_b (N m^2 s)", *(f"{e:g}" for e in etas)],
                    [[f"{kn:g}", *(text(cell[kn, e]) for e in etas)] for kn in kns])


def stability_markdown(rows: list[dict], duration: float) -> str:
    lines = grid_lines(rows, lambda r: f"ok, {r['e2_rms'] * 1e3:.2f} mm" if r["status"] == "ok"
                       else f"{r['t_end']:.3f} s")
    lines += ["", f"cells: 'ok, e2 RMS' if the {duration:g} s run finished, else the time it diverged"]
    return "\n".join(lines)


def plot_stability_map(maps: dict[str, list[dict]], duration: float, path) -> Path:
    """One heatmap of survival time per named map (e.g. 'chain, servo'), log axes of k_n and eta_b."""
    fig, axes = pyplot().subplots(1, len(maps), figsize=(4.2 * len(maps), 3.6), squeeze=False)
    for ax, (name, rows) in zip(axes[0], maps.items(), strict=True):
        kns, etas, cell = _grid(rows)
        Z = np.array([[cell[k, e]["t_end"] for e in etas] for k in kns])
        im = ax.imshow(Z, origin="lower", cmap="viridis", vmin=0, vmax=duration, aspect="auto")
        ax.set_xticks(range(len(etas)), [f"{e:g}" for e in etas])
        ax.set_yticks(range(len(kns)), [f"{k:g}" for k in kns])
        ax.set(xlabel="eta_b (N m^2 s)", ylabel="k_n")
        ax.set_title(name, fontsize=9)
        for (i, j), z in np.ndenumerate(Z):
            r = cell[kns[i], etas[j]]
            ax.text(j, i, "ok" if r["status"] == "ok" else f"{r['t_end']:.2f}", ha="center", va="center",
                    fontsize=7, color="w" if z < 0.6 * duration else "k")
    fig.colorbar(im, ax=axes[0].tolist(), label="survival time (s)")
    return save_figure(fig, path)


def predicted_map(kns, etas, overrides=(), times=(0.0,), say=lambda s: None) -> list[dict]:
    """`radius_along` over the k_n x eta_b grid of `harness.studies.stability_map` (same overrides and keys),
    sensing without noise: rows {kn, eta_b, radius, t, class, frequency_hz, dominant, reached, stopped}."""
    from harness.config.load import load_scenario

    rows = []
    for kn, eta in itertools.product(kns, etas):
        eta_s = f"[{eta},{eta},{eta}]"
        sets = [*overrides, "snr_db=none", f"gains.kn={kn}", f"plant.bending_viscosity={eta_s}"]
        row = {"kn": float(kn), "eta_b": float(eta), **radius_along(load_scenario(None, sets), times)}
        rows.append(row)
        say(f"kn = {kn:g}, eta_b = {eta:g}: rho = {row['radius']:.6f} at t = {row['t']:g} s "
            f"({row['class']}, {row['frequency_hz']:.1f} Hz)")
    return rows


def predicted_markdown(rows: list[dict], sim: list[dict] | None = None) -> str:
    """Table of the predicted map (spectral radius, class) next to the simulated one
    (`harness.studies.stability_map.stability_map` rows) when given."""
    simc = {(r["kn"], r["eta_b"]): r for r in (sim or [])}

    def text(r: dict) -> str:
        txt = f"rho {r['radius']:.4f} ({r['class']}" + (", flip)" if r["flip"] else ")")
        s = simc.get((r["kn"], r["eta_b"]))
        if s is not None:
            txt += " / sim: " + ("ok" if s["status"] == "ok" else f"diverged {s['t_end']:.3f} s")
        return txt

    return "\n".join(grid_lines(rows, text))


PREDICTED = "chain CC off, torque, no noise"  # the map `--predicted` linearizes


def main(out="runs/stability_map", duration: float = 3.0, predicted: bool = False) -> int:
    """`teleop stability-map`: the maps of MAPS over KNS x ETAS, stability_map.md and .png in `out`;
    `predicted`: also the PREDICTED map from the spectral radius along each run (every 0.25 s)."""
    maps, text, say = {}, [], printer(True)
    for name, ov in MAPS.items():
        maps[name] = stability_map(KNS, ETAS, ov, duration, say=lambda s, n=name: say(f"{n} {s}"))
        text.append(f"{name}\n\n" + stability_markdown(maps[name], duration))
    if predicted:
        times = [0.25 * i for i in range(int(duration / 0.25 + 1e-9) + 1)]
        pred = predicted_map(KNS, ETAS, MAPS[PREDICTED], times, say=lambda s: say(f"predicted {s}"))
        head = f"{PREDICTED}, predicted (largest spectral radius over t = 0, 0.25, ..., {times[-1]:g} s)"
        text.append(f"{head} / simulated\n\n" + predicted_markdown(pred, maps[PREDICTED]))
    save(Path(out) / "stability_map.md", "\n\n".join(text) + "\n")
    plot_stability_map(maps, duration, Path(out) / "stability_map.png")
    print("\n\n".join(text))
    return 0
