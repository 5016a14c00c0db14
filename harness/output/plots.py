"""PNG figures of one run (matplotlib `Figure` on an Agg canvas, no pyplot: safe in workers and headless):
e1 (11), e2 (16), beta (41) as the paper's Figs. 2-4, q2 with its ranges, arm shapes in world X-Z, and
forces.png (interaction forces true vs what the laws got, penetration; runs with interaction)."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from harness.config.textio import write_atomic
from harness.loop.trajectory import Trajectory
from harness.output import FIGURES
from harness.output import geometry as geo

DPI = 130
_SEC_COLORS = ("tab:green", "tab:purple", "tab:brown")
OBSTACLE_FACE, OBSTACLE_EDGE = (0.6, 0.63, 0.72, 0.35), (0.35, 0.38, 0.5, 1.0)


def _figure(nrows: int = 1, figsize=(7.0, 3.6)):
    """A Figure on an Agg canvas at the save DPI (constrained layout) and its `nrows` axes sharing x."""
    fig = Figure(figsize=figsize, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, 1, sharex=True, squeeze=False)[:, 0]


def _plot_series(ax, t, y, *args, **kwargs):
    """ax.plot of one time series (every sample)."""
    t, y = np.asarray(t, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
    return ax.plot(t, y, *args, **kwargs)


def _status_note(fig: Figure, traj: Trajectory) -> None:
    if traj.status != "ok":
        end = f" at t = {traj.t[-1]:.4g} s" if len(traj) else " before the first step"
        fig.suptitle(f"run ended with status {traj.status!r}{end}", color="tab:red", fontsize=9)


def _finish_time_axis(ax, traj: Trajectory) -> None:
    ax.set_xlabel("time t [s]")
    ax.grid(True, alpha=0.3)
    if len(traj) == 1:
        ax.set_xlim(traj.t[0] - 0.5, traj.t[0] + 0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)


def _save(fig: Figure, path: Path) -> Path:
    """Save under a temporary name, renamed into place when complete (zlib level 1: the same pixels)."""
    return write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=DPI, format=Path(path).suffix[1:] or "png",
                                                      pil_kwargs={"compress_level": 1}))


def _marker(traj: Trajectory) -> str | None:
    return "." if len(traj) <= 2 else None  # a single sample is invisible as a line


def _time_figure(traj: Trajectory, path: Path, title: str, ylabel: str, lines, extra=None) -> Path:
    """One time-series figure: lines = [(values (n,), plot args, plot kwargs)]; extra(ax) draws more."""
    fig, (ax,) = _figure()
    for y, args, kw in lines:
        _plot_series(ax, traj.t, y, *args, marker=_marker(traj), **kw)
    if extra is not None:
        extra(ax)
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    _finish_time_axis(ax, traj)
    _status_note(fig, traj)
    return _save(fig, path)


def _xz_lines(values, label: str, colors=("tab:blue", "tab:orange"), style=()) -> list:
    v = np.asarray(values, dtype=float).reshape(-1, 2)
    return [(v[:, j], style, dict(color=colors[j], label=label.format("XZ"[j]))) for j in range(2)]


def fig_e1(traj: Trajectory, path: Path) -> Path:
    return _time_figure(traj, path, "Master tracking error e1 = x_d - x1 (eq. 11)", "e1 [m]",
                        _xz_lines(traj.e1, "e1 {}"))


def fig_e2(traj: Trajectory, path: Path) -> Path:
    lines = _xz_lines(traj.e2, "e2 {} (analytic x2 of sensed q2)")
    if traj.x2_plant is not None:
        tipname = "rod tip" if (traj.meta or {}).get("plant") == "cosserat" else "MuJoCo tip"
        lines += _xz_lines(traj.e2_plant, f"{{}}, x1 - x2_plant ({tipname})", ("tab:cyan", "tab:red"),
                           ("--",))
    return _time_figure(traj, path, "Master-slave coordination error e2 = x1 - x2 (eq. 16)", "e2 [m]", lines)


def fig_beta(traj: Trajectory, path: Path) -> Path:
    # J2 has dimensionless d-columns and m^2 k-columns, so beta carries no single physical unit
    return _time_figure(traj, path, "Slave manipulability beta = sqrt(det(J2 J2^T)) (eq. 41)",
                        "beta [mixed units]",
                        [(np.asarray(traj.beta, dtype=float).reshape(-1), (), dict(color="tab:green",
                                                                                   label="beta(q2)"))],
                        extra=lambda ax: ax.axhline(0.0, color="k", lw=0.8))


def fig_q2(traj: Trajectory, path: Path) -> Path:
    fig, (ax_d, ax_k) = _figure(2, figsize=(8.0, 5.6))
    q2 = np.asarray(traj.q2, dtype=float).reshape(len(traj), 6)
    meta = traj.meta or {}
    m = _marker(traj)
    lr = meta.get("length_range")  # (lo (3,), hi (3,)) m
    lr = None if lr is None else np.asarray(lr, dtype=float).reshape(2, 3)
    max_bend = meta.get("max_bend")
    for i, c in enumerate(_SEC_COLORS):
        _plot_series(ax_d, traj.t, q2[:, i], color=c, marker=m, label=f"d{i + 1}")
        _plot_series(ax_k, traj.t, q2[:, 3 + i], color=c, marker=m, label=f"k{i + 1}")
        if lr is not None:
            ax_d.axhspan(lr[0][i], lr[1][i], color=c, alpha=0.07)
            for v in (lr[0][i], lr[1][i]):
                ax_d.axhline(v, color=c, ls="--", lw=0.8)
        if max_bend is not None and len(traj):
            with np.errstate(divide="ignore", invalid="ignore"):
                kmax = float(max_bend) / q2[:, i]  # |k_i d_i| <= max_bend
            _plot_series(ax_k, traj.t, kmax, ls="--", lw=0.8, color=c)
            _plot_series(ax_k, traj.t, -kmax, ls="--", lw=0.8, color=c)
    if lr is not None:
        ax_d.plot([], [], "k--", lw=0.8, label="allowed range")
    k = q2[:, 3:][np.isfinite(q2[:, 3:])]
    d = q2[:, :3][np.isfinite(q2[:, :3]) & (q2[:, :3] > 0)]
    label = "+-max_bend / d_i"
    if k.size:  # data first; the bend-limit curves shown unless they are far outside the data
        span = max(float(np.abs(k).max()), 1e-3)
        lim = span
        if max_bend is not None and d.size:
            lim = max(span, min(float(max_bend) / float(d.min()), 10.0 * span))
            if float(max_bend) / float(d.max()) > 1.1 * lim:  # the limit curves are off the scale
                label += f":\noff scale (>= {float(max_bend) / float(d.max()):.2g} 1/m)"
        ax_k.set_ylim(-1.1 * lim, 1.1 * lim)
    if max_bend is not None:
        ax_k.plot([], [], "k--", lw=0.8, label=label)
    ax_d.set_title("Slave section lengths d_i (q2[0:3])")
    ax_d.set_ylabel("d [m]")
    ax_k.set_title("Slave section curvatures k_i (q2[3:6]); limit |k_i d_i| <= max_bend")
    ax_k.set_ylabel("k [1/m]")
    ax_d.grid(True, alpha=0.3)
    ax_d.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    _finish_time_axis(ax_k, traj)
    if ax_k.get_legend() is not None:  # outside the axes: the limit curves leave no free corner
        ax_k.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    _status_note(fig, traj)
    return _save(fig, path)


def _slave_xz(traj: Trajectory, i: int, fn: Callable | None, base: np.ndarray) -> np.ndarray | None:
    """(P, 2) world X-Z of the slave backbone at step i (backbone_fn, else analytic CC of q2)."""
    q2 = np.asarray(traj.q2[i], dtype=float)
    if not np.all(np.isfinite(q2)):
        return None
    if fn is not None:
        try:
            pts = np.asarray(fn(q2), dtype=float)
            if pts.ndim == 2 and pts.shape[1] == 2:
                return pts + base[[0, 2]]
            warnings.warn(f"backbone_fn returned shape {pts.shape}, expected (P, 2)", stacklevel=3)
        except Exception as exc:  # plotting must not kill a run's post-processing
            warnings.warn(f"backbone_fn failed ({exc!r}); using the analytic backbone", stacklevel=3)
    return geo.cc_backbone(q2[None])[0] + base[[0, 2]]


def fig_shapes(traj: Trajectory, path: Path) -> Path:
    """Master links and slave backbone at 5 instants, world X-Z plane."""
    meta = traj.meta or {}
    mb, sb = geo.world_base(meta, "master_base"), geo.world_base(meta, "slave_base")
    master = geo.master_points(traj, mb)[:, :, [0, 2]]  # (n, 3, 2) world X-Z of base, elbow, tip
    fn = meta.get("backbone_fn")
    fn = fn if callable(fn) else None
    fig, (ax,) = _figure(1, (7.5, 5.0))
    n = len(traj)
    if n == 0:
        ax.text(0.5, 0.5, "no steps recorded", ha="center", va="center", transform=ax.transAxes)
    idx = np.unique(np.linspace(0, n - 1, min(5, n)).round().astype(int)) if n else []
    cmap = colormaps["viridis"]
    rod = meta.get("geometry", {}).get("centreline")  # Cosserat plant: (n, nodes, 3) world
    for j, i in enumerate(idx):
        c = cmap(j / max(1, len(idx) - 1))
        ax.plot(master[i, :, 0], master[i, :, 1], "-o", color=c, lw=2.5, ms=4, label=f"t = {traj.t[i]:.3g} s")
        sxz = _slave_xz(traj, i, fn, sb)
        if sxz is not None:
            ax.plot(sxz[:, 0], sxz[:, 1], "-", color=c, lw=2.0)
        if traj.body_pos is not None:
            bp = np.asarray(traj.body_pos[i], dtype=float)
            ax.plot(bp[:, 0], bp[:, 2], "o", mfc="none", color=c, ms=3.5)
        if rod is not None:
            ax.plot(rod[i][:, 0], rod[i][:, 2], ":", color=c, lw=2.5)
        xd = np.asarray(traj.xd[i], dtype=float)
        ax.plot(*(xd + mb[[0, 2]]), "x", color=c, ms=7)
        ax.plot(*(xd + sb[[0, 2]]), "x", color=c, ms=7)
    if n:
        ax.plot([], [], "k-o", lw=2.5, ms=4, label="master links (base, elbow, tip)")
        ax.plot([], [], "k-", lw=2.0, label="slave backbone (analytic, sensed q2)")
        if traj.body_pos is not None:
            ax.plot([], [], "ko", mfc="none", ms=3.5, label="plant bodies (MuJoCo)")
        if rod is not None:
            ax.plot([], [], "k:", lw=2.5, label="Cosserat rod centreline (plant)")
        ax.plot([], [], "kx", ms=7, label="desired tip x_d (40)")
        ax.plot(*mb[[0, 2]], "ks", ms=7)
        ax.plot(*sb[[0, 2]], "ks", ms=7)
    for j, ob in enumerate(meta.get("environment") or ()):  # filled outlines, slave task frame at its base
        xz = geo.obstacle_outline(ob) + sb[[0, 2]]
        ax.add_patch(Polygon(xz, closed=True, facecolor=OBSTACLE_FACE, edgecolor=OBSTACLE_EDGE, hatch="//",
                             lw=1.0, label="obstacle" if j == 0 else None, zorder=0))
        ax.update_datalim(xz)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("world X [m]")
    ax.set_ylabel("world Z [m]")
    ax.set_title("Arm shapes: rigid master and continuum slave, world X-Z plane")
    ax.grid(True, alpha=0.3)
    if n:
        ax.legend(loc="best", fontsize=7)
    _status_note(fig, traj)
    return _save(fig, path)


def fig_forces(traj: Trajectory, path: Path) -> Path:
    """F2 (slave tip) and F1 (master handle), true (solid) vs what the laws (13), (17) got (thin), and the
    maximum penetration of the arm into the environment objects (mm)."""
    fig, axes = _figure(3, figsize=(7.0, 7.5))
    m = _marker(traj)
    ft, fs = np.asarray(traj.F_true, dtype=float), np.asarray(traj.F_sensed, dtype=float)
    for ax, off, who in ((axes[0], 2, "F2 on the slave tip (contact + constant)"),
                         (axes[1], 0, "F1 on the master handle (operator grip + constant)")):
        for j, (lab, c) in enumerate((("X", "tab:blue"), ("Z", "tab:orange"))):
            _plot_series(ax, traj.t, ft[:, off + j], color=c, marker=m, label=f"true {lab}")
            _plot_series(ax, traj.t, fs[:, off + j], color=c, lw=0.7, alpha=0.6, ls="--",
                         label=f"to the law {lab}")
        ax.set_title(who, fontsize=10)
        ax.set_ylabel("force [N]")
        _finish_time_axis(ax, traj)
    pen = np.maximum(0.0, -np.asarray(traj.contact, dtype=float)[:, 3]) * 1e3
    _plot_series(axes[2], traj.t, pen, color="tab:red", marker=m, label="max penetration")
    axes[2].set_title("Penetration of the arm into the environment", fontsize=10)
    axes[2].set_ylabel("[mm]")
    _finish_time_axis(axes[2], traj)
    _status_note(fig, traj)
    return _save(fig, path)


def figure_names(traj: Trajectory) -> list[str]:
    """The files `write_figures(traj, ...)` writes by default: FIGURES (forces.png only with interaction)."""
    return [n for n in FIGURES if n != "forces.png" or geo.has_interaction(traj)]


def write_figures(traj: Trajectory, outdir: str | Path, *, names: Iterable[str] | None = None) -> list[Path]:
    """Write the PNG figures of `traj` into `outdir` (created); returns their paths (FIGURES order).
    names: the FIGURES to draw (None: `figure_names(traj)`; one that does not apply to this run is
    skipped; one not in FIGURES raises ValueError)."""
    applicable = figure_names(traj)
    if names is not None:
        names = list(names)
        if unknown := [n for n in names if n not in FIGURES]:
            raise ValueError(f"names = {unknown!r}: unknown figure name(s); allowed: {', '.join(FIGURES)}")
        applicable = [n for n in applicable if n in names]
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    draw = {"fig2_e1.png": fig_e1, "fig3_e2.png": fig_e2, "fig4_beta.png": fig_beta, "q2.png": fig_q2,
            "shapes.png": fig_shapes, "forces.png": fig_forces}
    return [draw[n](traj, outdir / n) for n in applicable]
