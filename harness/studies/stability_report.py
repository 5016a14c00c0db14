"""Outputs of the linear stability analysis: mode shapes on the arm, the spectrum files, and the spectral
radius along a run (`radius_along`, which `harness.studies.stability_map` predicts its map from)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from harness.config.scenario import Scenario
from harness.studies.figures import pyplot, save, save_csv, save_figure
from harness.studies.stability import ClosedLoopMap, LinearizationError, Stability, linearize


def mode_shape(res: Stability, j: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(rest (m, 2), displaced (m, 2), scale): the slave's points [X, Z] (m) at the point of linearization
    and along the real part of mode j (phase maximising it), largest displacement 5 % of the arm's length."""
    v = res.eigenvectors[: res.n_plant, j]
    phase = np.exp(-0.5j * np.angle(np.sum(v * v))) if np.any(v) else 1.0
    vr = np.real(v * phase)
    x0 = res.x0[: res.n_plant]
    pos = res.shapes["positions"]
    slave = res.shapes["slave"]
    p0 = pos(x0, slave)
    eps = 1e-6 / max(np.abs(vr).max(), 1e-300)
    dp = np.abs(pos(x0 + eps * vr, slave) - p0).max() / eps
    scale = 0.05 * float(np.sum(slave.rest_lengths)) / max(dp, 1e-300)
    return p0, pos(x0 + scale * vr, slave), float(scale)


def plot_stability(res: Stability, path, n_modes: int = 2) -> Path:
    """Figure: the spectrum against the unit circle (left) and the shapes of the n_modes least stable modes
    on the slave (right)."""
    fig, axes = pyplot().subplots(1, 1 + n_modes, figsize=(4.2 * (1 + n_modes), 4.0))
    ax = axes[0]
    th = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(th), np.sin(th), "k-", lw=0.6)
    ev = res.eigenvalues
    ax.plot(ev.real, ev.imag, "x", ms=5)
    ax.plot(ev[0].real, ev[0].imag, "ro", mfc="none", ms=9)
    ax.set(aspect="equal", xlabel="Re lambda", ylabel="Im lambda")
    ax.set_title(f"one-period spectrum, rho = {res.radius:.5f}", fontsize=9)
    for j, ax in enumerate(axes[1:]):
        j = min(j if j == 0 else _next_distinct(res, j), len(ev) - 1)
        p0, p1, sc = mode_shape(res, j)
        ax.plot(p0[:, 0], p0[:, 1], "k.-", lw=1, ms=3, label="at t")
        ax.plot(p1[:, 0], p1[:, 1], "r.-", lw=1, ms=3, label=f"mode x {sc:.3g}")
        half = 0.6 * float(np.ptp(p0[:, 1]) or 1.0)
        ax.set_xlim(float(p0[:, 0].mean()) - half, float(p0[:, 0].mean()) + half)
        ax.set(aspect="equal", adjustable="box", xlabel="X (m)", ylabel="Z (m)")
        ax.set_title(f"|lambda| = {abs(ev[j]):.5f}, {res.frequency(j):.1f} Hz\n"
                     + ", ".join(n.removeprefix("octarm_") for n, _ in res.dominant(j, 3)), fontsize=7)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def _next_distinct(res: Stability, j: int) -> int:
    """Index of the j-th mode counting a complex pair once."""
    idx, seen = 0, 0
    ev = res.eigenvalues
    while idx < len(ev) - 1 and seen < j:
        idx += 2 if abs(ev[idx].imag) > 1e-12 and abs(ev[idx + 1] - np.conj(ev[idx])) < 1e-9 else 1
        seen += 1
    return idx


def write_stability(res: Stability, out) -> list[Path]:
    """spectrum.csv (every eigenvalue: real, imag, modulus, angle, frequency, growth, dominant states),
    stability.json (verdict, radius, least stable mode, t, T, h, MuJoCo's warnings: count and first text)
    and stability.png in folder `out`."""
    import json

    from harness.config.textio import jsonable

    out = Path(out)
    rows = res.spectrum_rows()
    summary = {"verdict": res.verdict(), "class": res.verdict_class, "spectral_radius": res.radius,
               "t": res.t, "control_dt": res.T, "fd_step": res.h, "n_states": len(res.names),
               "least_stable": rows[0], "dominant": res.dominant(0, 6),
               "most_negative": rows[res.most_negative()],
               "plant": res.scenario.plant.kind, "actuation": res.scenario.plant.actuation}
    return [save_csv(out / "spectrum.csv", rows),
            save(out / "stability.json", json.dumps(jsonable(summary), indent=2) + "\n"),
            plot_stability(res, out / "stability.png")]


def _along(scn: Scenario, times, h=None, on_point=lambda res: None) -> tuple[Stability | None, str]:
    """`linearize` at each of `times` (s, increasing) on one run of `scn`: (the point of largest spectral
    radius or None, why the run stopped before the next point or "")."""
    loop = ClosedLoopMap(scn)
    worst = None
    for t in times:
        try:
            res = linearize(scn, float(t), h, loop=loop)
        except LinearizationError as exc:
            return worst, str(exc)
        on_point(res)
        if worst is None or res.radius > worst.radius:
            worst = res
    return worst, ""


def radius_along(scn: Scenario, times) -> dict:
    """The least stable linearization along one run of `scn`: {radius, t, class, frequency_hz, dominant,
    reached (last time linearized), stopped, flip}; class "not reached" if the first time was not."""
    reached = []
    res, stopped = _along(scn, times, on_point=lambda r: reached.append(r.t))
    if res is None:
        nan = float("nan")
        return {"radius": nan, "t": nan, "class": "not reached", "frequency_hz": nan, "dominant": "",
                "reached": nan, "stopped": stopped, "flip": False}
    return {"radius": res.radius, "t": res.t, "class": res.verdict_class, "frequency_hz": res.frequency(0),
            "dominant": ";".join(n for n, _ in res.dominant(0, 3)), "reached": reached[-1],
            "stopped": stopped, "flip": bool(abs(np.angle(res.eigenvalues[0])) > 0.99 * math.pi)}


__all__ = ["mode_shape", "plot_stability", "radius_along",
           "write_stability"]


def print_modes(res, modes: int) -> None:
    """`teleop stability --at T`: the verdict, the `modes` least stable modes and the most negative one."""
    print(res.verdict())
    print(f"{len(res.names)} states; least stable modes (|lambda|, angle, Hz, growth 1/s, dominant):")
    for j in range(min(modes, len(res.eigenvalues))):
        lam = res.eigenvalues[j]
        dom = ", ".join(f"{n} {w:.2f}" for n, w in res.dominant(j, 4))
        print(f"  {abs(lam):.6f}  {math.atan2(lam.imag, lam.real):+.4f}  {res.frequency(j):8.2f}  "
              f"{res.growth_rate(j):+9.3g}  {dom}")
    j = res.most_negative()
    lam = res.eigenvalues[j]
    print(f"most negative eigenvalue: {lam.real:+.6f}{lam.imag:+.6f}j ({res.frequency(j):.2f} Hz), on "
          + ", ".join(n for n, _ in res.dominant(j, 4)))


def least_stable_along(scn, times, h, out):
    """`teleop stability --at T1,T2,...`: one run linearized at each time (a table printed), the least stable
    point's files in `out`; returns it with `.stopped` (why the run ended early, or "").  Raises
    LinearizationError when not even the first time could be linearized."""
    def row(res) -> None:
        dom = ", ".join(n for n, _ in res.dominant(0, 3))
        print(f"{res.t:6.3f}  {res.radius:.6f}  {res.verdict_class:8s}  {res.frequency(0):7.2f}  {dom}")

    print("t (s)   radius     class     Hz       dominant")
    worst, stopped = _along(scn, times, h, row)
    if worst is None:
        raise LinearizationError(stopped)
    write_stability(worst, out)
    print(f"least stable: {worst.verdict()}")
    if stopped:
        print(f"stopped: {stopped}")
    worst.stopped = stopped
    return worst
