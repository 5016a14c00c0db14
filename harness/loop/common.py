"""What every closed loop shares: the stop flag, the initial state, the desired
trajectory, the seeded noise table, the controller-side packed arrays and the run metadata.

Used by the plant-specific loops (`harness.loop.analytic_loop`, `harness.loop.mujoco_loop`); it
imports neither of them (the dispatch is `harness.loop.simulate`).
"""

from __future__ import annotations

import threading
from functools import partial
from typing import NamedTuple

import numpy as np

from controllers import master as master_model
from controllers import slave as slave_model
from controllers.slave import gauss_legendre01
from controllers.status import Status
from controllers.subtasks import pack_subtask
from harness.config.runtime import progress_bar_class
from harness.config.scenario import Scenario
from harness.loop.fast import K
from harness.loop.force_kernels import filter_alpha
from harness.loop.kernels import DQ2_FILTER
from harness.loop.trajectory import Trajectory
from harness.plant.initial import InitialStateError
from harness.plant.initial import initial_state as _initial_state

STOP = threading.Event()  # set from a signal handler to stop a run cleanly
CHUNK = 250  # control steps per compiled call between progress/interrupt checks

def set_outcome(traj: Trajectory, status: int, interrupted: bool, error: str = "", detail: str = "") -> None:
    """Set traj.status/message from a loop's end: an exception text (`error`), a kernel status code
    (`controllers.status.Status`, plus `detail`), an interrupt, or nothing (status stays "ok")."""
    t_end = float(traj.t[-1]) if len(traj) else 0.0
    if error:
        traj.status, cause = "error", error
    elif status != 0:
        known = status in Status._value2member_map_
        traj.status, cause = "diverged", (Status(status).text if known else "unknown") + detail
    elif interrupted:
        traj.status, cause = "interrupted", "interrupted"
    else:
        return
    traj.message = f"{cause} at t = {t_end:.4f} s"


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
    """[q1, dq1, q2, dq2] (16,) at t = 0, both arms at rest (`harness.plant.initial.initial_state`);
    raises SimulationError when the start is impossible."""
    try:
        return _initial_state(scn)
    except InitialStateError as exc:
        raise SimulationError(str(exc)) from None


def noise_table(scn: Scenario, n: int) -> tuple[np.ndarray, float]:
    """Seeded standard-normal noise and the SNR scale 10^(-SNR/20) (0 = no noise).

    ``noise_model = "per_vector"``: (n, 16).  ``"per_channel"`` (default): (n, 32), the same normals in
    columns 0:16 and, in row 0, columns 16:32, the running sums of squares of each true signal that
    `kernels.add_noise_channel` updates (so a fresh table per run).  Same seed -> same normals in both
    models.  With ``sensing.dq2_cutoff``, DQ2_FILTER more columns follow: row 0 holds the filter gain
    (`force_kernels.filter_alpha`) and the filtered dq2 (`kernels.sense_state`)."""
    if scn.snr_db is None:
        normals, scale = np.zeros((1, 16)), 0.0
    else:
        normals = np.random.default_rng(scn.seed).standard_normal((n, 16))
        if scn.noise_model == "per_channel":
            normals = np.concatenate([normals, np.zeros((n, 16))], axis=1)
        scale = float(10.0 ** (-scn.snr_db / 20.0))
    if scn.sensing.dq2_cutoff is not None:
        normals = np.concatenate([normals, np.zeros((normals.shape[0], DQ2_FILTER))], axis=1)
        normals[0, -DQ2_FILTER] = filter_alpha(scn.sensing.dq2_cutoff, scn.control_dt)
    return normals, scale


class ChunkRun:
    """Drives a compiled loop over a run's control steps in calls of `size` steps (`run`), keeping where it is
    (status, done, interrupted) up to date, so that a caller that catches an exception still knows how many
    steps were recorded."""

    def __init__(self, n: int, size: int, bar=None, on_part=None):
        self.n, self.size, self.bar, self.on_part = n, size, bar, on_part
        self.status, self.done, self.interrupted = 0, 0, False

    def run(self, call) -> None:
        """call(k, k1) -> (status, steps done) runs steps k..k1-1.  After each call: the progress bar,
        on_part(k, done) when steps were done; stops at a non-zero status or when STOP is set."""
        k = 0
        while k < self.n:
            k1 = min(self.n, k + self.size)
            self.status, m = call(k, k1)
            self.done = k + m
            if self.bar is not None:
                self.bar.update(m)
            if self.on_part is not None and m:
                self.on_part(k, self.done)
            if self.status != 0:
                return
            k = k1
            if STOP.is_set():
                self.interrupted = True
                return


def progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None
    try:
        bar = progress_bar_class()
    except ImportError:  # pragma: no cover
        return None
    return bar(total=total, desc=desc, unit="step", unit_scale=True, leave=False)


class RunModel(NamedTuple):
    """A scenario compiled once per run (frozen, like Pinocchio's / MuJoCo's model): the controller-side
    packed parameters, the quadrature, the constant forces, the desired trajectory and the initial state.
    The loops, the plants' adapters and the controller context read it; per-run buffers (noise table,
    record rows, command ring) are made by each run.

    mpk_c: master params (`controllers.master.packed`), spk_c: slave params (`SlaveParams.packed`),
    nodes, weights: Gauss-Legendre on [0, 1] (slave.n_quad,), gains: packed gains + [e2_sign,
    null_space_scale], spec: packed sub-task (`controllers.subtasks.pack_subtask`), F (4,) N: constant
    tip forces [F1, F2], traj (5,): desired-trajectory parameters, s0 (16,): [q1, dq1, q2, dq2] at t = 0."""

    mpk_c: np.ndarray
    spk_c: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    gains: np.ndarray
    spec: np.ndarray
    F: np.ndarray
    traj: np.ndarray
    s0: np.ndarray


def compile_model(scn: Scenario) -> RunModel:
    """The `RunModel` of `scn` (raises SimulationError when the start is impossible)."""
    nodes, weights = gauss_legendre01(scn.slave.n_quad)
    F = np.array([*scn.interaction_forces[0], *scn.interaction_forces[1]], dtype=float)
    return RunModel(
        mpk_c=master_model.packed(scn.master), spk_c=scn.slave.packed(), nodes=nodes, weights=weights,
        gains=np.concatenate([scn.gains.packed(), [float(scn.faults.e2_sign), scn.faults.null_space_scale]]),
        spec=pack_subtask(scn.subtask, scn.slave), F=F, traj=trajectory_params(scn), s0=initial_state(scn))


def run_meta(scn: Scenario, wall: float) -> dict:
    lo, hi = scn.slave.length_range
    return {
        "plant": scn.plant.kind, "wall_time": wall, "control_dt": scn.control_dt,
        "master_lengths": scn.plant_master.lengths, "length_range": (lo.tolist(), hi.tolist()),
        "max_bend": scn.slave.max_bend, "backbone_fn": partial(slave_model.backbone, scn.slave),  # picklable
        "master_base": (0.0, 0.0, 0.0), "slave_base": (0.0, 0.0, 0.0), "mujoco_warnings": 0,
    }
