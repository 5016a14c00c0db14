"""Closed-loop simulation: the paper's controllers (on the nominal analytic models) driving either
the analytic plant (RK4) or the MuJoCo plant.  Returns an in-memory `Trajectory`; side effects
(recordings, figures, files) are left to the callers.

A run that diverges (non-finite numbers, MuJoCo instability warnings, singular Jacobians, runaway
errors) or is interrupted (`STOP` set, e.g. by SIGINT) stops and returns everything up to that
point with `status` and `message` saying what happened and when.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from controllers import master as master_model
from controllers import slave as slave_model
from controllers.slave import gauss_legendre01
from controllers.subtasks import pack_subtask

from .config import Scenario
from .fast import K
from .trajectory import ROW_WIDTH, Trajectory

STOP = threading.Event()  # set from a signal handler to stop a run cleanly
CHUNK = 250  # control steps per compiled call between progress/interrupt checks

STATUS_TEXT = {
    1: "non-finite state or command",
    2: "master Jacobian J1 singular",
    3: "slave J2 J2^T singular",
    4: "runaway tracking error (|e| > 1 m)",
    5: "slave section length <= 0",
    6: "non-finite or exploding MuJoCo state (|x| > 1e6)",
    7: "MuJoCo warning",
}


class SimulationError(RuntimeError):
    """Bad initial conditions that make a run impossible (reported before any stepping)."""


def trajectory_params(scn: Scenario) -> np.ndarray:
    tr = scn.trajectory
    return np.array([tr.center[0], tr.center[1], tr.amplitude[0], tr.amplitude[1], tr.omega])


def desired_at(scn: Scenario, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xd, dxd, ddxd = np.empty(2), np.empty(2), np.empty(2)
    K.desired(trajectory_params(scn), float(t), xd, dxd, ddxd)
    return xd, dxd, ddxd


def initial_state(scn: Scenario) -> np.ndarray:
    """[q1, dq1, q2, dq2] (16,) at t = 0, both arms at rest.

    Master: inverse kinematics of x_d(0) + initial.master_offset (plant master geometry).
    Slave: initial.slave_q2, or equal section lengths with curvature initial.slave_curvature each,
    the length chosen (Newton on Z) so that the tip height equals the master tip's.
    """
    xd0, _, _ = desired_at(scn, 0.0)
    x0 = xd0 + np.asarray(scn.initial.master_offset, dtype=float)
    pm = scn.plant_master
    try:
        q1 = master_model.ik(pm, x0, scn.initial.master_elbow)
    except ValueError as exc:
        raise SimulationError(f"initial.master_offset: {exc}") from None
    x1 = master_model.fk(pm, q1)
    ps = scn.plant_slave
    if scn.initial.slave_q2 is not None:
        q2 = np.asarray(scn.initial.slave_q2, dtype=float)
    else:
        kappa = scn.initial.slave_curvature
        d = float(np.mean(ps.rest_lengths))
        for _ in range(50):
            q2 = np.array([d, d, d, kappa, kappa, kappa])
            z = slave_model.tip_position(ps, q2)[1]
            dz = slave_model.jacobian(ps, q2)[1, :3].sum()
            step = (x1[1] - z) / dz
            d += step
            if abs(step) < 1e-14:
                break
        q2 = np.array([d, d, d, kappa, kappa, kappa])
        lo, hi = ps.length_range
        if np.any(q2[:3] < lo - 1e-12) or np.any(q2[:3] > hi + 1e-12):
            raise SimulationError(
                f"trajectory.center: the slave cannot start under the master tip (Z = {x1[1]:.3f} m "
                f"needs section lengths {d:.3f} m outside [{lo.min():.3f}, {hi.max():.3f}] m)")
    return np.concatenate([q1, np.zeros(2), q2, np.zeros(6)])


def noise_table(scn: Scenario, n: int) -> tuple[np.ndarray, float]:
    """Standard-normal noise (n, 16), seeded, and the SNR scale 10^(-SNR/20) (0 = no noise)."""
    if scn.snr_db is None:
        return np.zeros((1, 16)), 0.0
    rng = np.random.default_rng(scn.seed)
    return rng.standard_normal((n, 16)), float(10.0 ** (-scn.snr_db / 20.0))


def _progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=total, desc=desc, unit="step", unit_scale=True, leave=False)


def simulate(scn: Scenario, progress: bool = False, on_chunk=None) -> Trajectory:
    """Run one scenario; dispatches on scn.plant.kind.  on_chunk: optional callable receiving each
    finished chunk of steps as a `Trajectory` (with the plant's meta), e.g. harness.viewer.LiveView."""
    if scn.plant.kind == "analytic":
        return simulate_analytic(scn, progress=progress, on_chunk=on_chunk)
    from .mujoco_sim import simulate_mujoco

    return simulate_mujoco(scn, progress=progress, on_chunk=on_chunk)


def common_arrays(scn: Scenario):
    """Packed controller-side arrays shared by both plants."""
    nodes, weights = gauss_legendre01(scn.slave.n_quad)
    F = np.array([*scn.interaction_forces[0], *scn.interaction_forces[1]], dtype=float)
    return dict(
        mpk_c=master_model.packed(scn.master), spk_c=scn.slave.packed(), nodes=nodes, weights=weights,
        gains=np.concatenate([scn.gains.packed(), [float(scn.faults.e2_sign), scn.faults.null_space_scale]]),
        spec=pack_subtask(scn.subtask, scn.slave), F=F,
        traj=trajectory_params(scn))


def simulate_analytic(scn: Scenario, progress: bool = False, on_chunk=None) -> Trajectory:
    """Closed loop on the analytic plant (plant params may differ from the controller's)."""
    n = scn.n_steps
    state = initial_state(scn)
    noise, scale = noise_table(scn, n)
    a = common_arrays(scn)
    rows = np.zeros((n, ROW_WIDTH))
    mpk_p = master_model.packed(scn.plant_master)
    spk_p = scn.plant_slave.packed()
    nsub = max(1, scn.substeps)
    bar = _progress_bar(progress, n, "analytic plant")
    status, done, k = 0, 0, 0
    t0 = time.perf_counter()
    interrupted = False
    error = ""
    try:
        while k < n:
            k1 = min(n, k + CHUNK)
            status, m = K.analytic_chunk(state, k, k1, scn.control_dt, nsub, scn.continuous_control,
                                         a["traj"], noise, scale, a["F"], a["mpk_c"], a["spk_c"], mpk_p,
                                         spk_p, a["nodes"], a["weights"], a["gains"], a["spec"], rows[k:k1])
            done = k + m
            if bar is not None:
                bar.update(m)
            if on_chunk is not None and m:
                part = Trajectory.from_rows(rows[k:done])
                part.meta.update(_meta(scn, 0.0))
                on_chunk(part)
            if status != 0:
                break
            k = k1
            if STOP.is_set():
                interrupted = True
                break
    except KeyboardInterrupt:
        interrupted = True
    except Exception as exc:  # keep what was computed; report the cause
        error = f"{type(exc).__name__}: {exc}"
    finally:
        if bar is not None:
            bar.close()
    traj = Trajectory.from_rows(rows[:done])
    traj.meta.update(_meta(scn, time.perf_counter() - t0))
    t_end = traj.t[-1] if done else 0.0
    if error:
        traj.status = "error"
        traj.message = f"{error} at t = {t_end:.4f} s"
    elif status != 0:
        traj.status = "diverged"
        traj.message = f"{STATUS_TEXT.get(status, 'unknown')} at t = {t_end:.4f} s"
    elif interrupted:
        traj.status = "interrupted"
        traj.message = f"interrupted at t = {t_end:.4f} s"
    return traj


def _meta(scn: Scenario, wall: float) -> dict:
    lo, hi = scn.slave.length_range
    return {
        "plant": scn.plant.kind, "wall_time": wall, "control_dt": scn.control_dt,
        "master_lengths": scn.plant_master.lengths, "length_range": (lo.tolist(), hi.tolist()),
        "max_bend": scn.slave.max_bend, "backbone_fn": lambda q2, p=scn.slave: slave_model.backbone(p, q2),
        "master_base": (0.0, 0.0, 0.0), "slave_base": (0.0, 0.0, 0.0), "mujoco_warnings": 0,
    }
