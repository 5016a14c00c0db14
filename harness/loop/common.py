"""What every closed loop shares: the run model, the stop flag, the desired trajectory, the seeded noise
table, the chunk driver and the run's outcome and metadata."""

from __future__ import annotations

import dataclasses
import threading
import time
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
from harness.loop.mj_warnings import warning_detail, warning_sink
from harness.loop.trajectory import Trajectory
from harness.plant.initial import InitialStateError, initial_state

STOP = threading.Event()  # set from a signal handler to stop a run cleanly
CHUNK = 250  # control steps between progress and interrupt checks


class SimulationError(RuntimeError):
    """Bad initial conditions that make a run impossible (reported before any stepping)."""


def trajectory_params(scn: Scenario) -> np.ndarray:
    tr = scn.trajectory
    return np.array([tr.center[0], tr.center[1], tr.amplitude[0], tr.amplitude[1], tr.omega])


def desired_at(scn: Scenario, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xd, dxd, ddxd = np.empty(2), np.empty(2), np.empty(2)
    K.desired(trajectory_params(scn), float(t), xd, dxd, ddxd)
    return xd, dxd, ddxd


def noise_table(scn: Scenario, n: int) -> tuple[np.ndarray, float]:
    """Seeded standard normals and the SNR scale 10^(-SNR/20) (0: no noise): (n, 16) per vector, (n, 32)
    per channel (`kernels.add_noise_channel`), + DQ2_FILTER columns with ``sensing.dq2_cutoff``
    (`kernels.sense_state`)."""
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
    """Drives a run's control steps (recorded into rows (n, ROW_WIDTH)) in calls of `size` steps, keeping
    status, done (steps recorded), interrupted, error / exc (an exception) and wall (s); closes the progress
    bar `bar` at the end.  on_chunk: called with each finished chunk as a `Trajectory` (the time series, +
    fill(piece, k0, k1))."""

    def __init__(self, scn: Scenario, rows: np.ndarray, size: int, bar=None, on_chunk=None, fill=None):
        self.scn, self.rows, self.n, self.size, self.bar = scn, rows, rows.shape[0], size, bar
        self.on_chunk, self.fill = on_chunk, fill
        self.status, self.done, self.interrupted, self.error, self.exc, self.wall = 0, 0, False, "", None, 0.0
        self.warnings: list[str] = []

    def run(self, call) -> None:
        """call(k, k1) -> (status, steps done) runs steps k..k1-1; then the bar and on_chunk.  Stops
        at a non-zero status, on STOP or a KeyboardInterrupt (interrupted) or an exception (error / exc).
        Keeps MuJoCo's warning text raised meanwhile (`warnings`)."""
        t0 = time.perf_counter()
        try:
            with warning_sink() as self.warnings:
                k = 0
                while k < self.n:
                    k1 = min(self.n, k + self.size)
                    self.status, m = call(k, k1)
                    self.done = k + m
                    if self.bar is not None:
                        self.bar.update(m)
                    if self.on_chunk is not None and m:
                        piece = Trajectory.from_rows(self.rows[k:self.done], meta=run_meta(self.scn, 0.0))
                        if self.fill is not None:
                            self.fill(piece, k, self.done)
                        self.on_chunk(piece)
                    if self.status != 0:
                        break
                    k = k1
                    if STOP.is_set():
                        self.interrupted = True
                        break
        except KeyboardInterrupt:
            self.interrupted = True
        except Exception as exc:  # keep what was computed; report the cause
            self.exc, self.error = exc, f"{type(exc).__name__}: {exc}"
        finally:
            if self.bar is not None:
                self.bar.close()
            self.wall = time.perf_counter() - t0

    def trajectory(self, warned: dict[str, int] | None = None) -> Trajectory:
        """The Trajectory of rows[:done]; status / message: an exception, a status code (+ the MuJoCo
        warnings `warned`, counts by name, and their text), an interrupt, or "ok"."""
        traj = Trajectory.from_rows(self.rows[:self.done], meta=run_meta(self.scn, self.wall))
        traj.meta["mujoco_warning_text"] = self.warnings[:20]
        if self.error:
            traj.status, cause = "error", self.error
        elif self.status != 0:
            known = self.status in {int(s) for s in Status}
            detail = warning_detail(warned or {}, self.warnings)
            traj.status, cause = "diverged", (Status(self.status).text if known else "unknown") + detail
        elif self.interrupted:
            traj.status, cause = "interrupted", "interrupted"
        else:
            return traj
        traj.message = f"{cause} at t = {float(traj.t[-1]) if len(traj) else 0.0:.4f} s"
        return traj


def progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None
    return progress_bar_class()(total=total, desc=desc, unit="step", unit_scale=True, leave=False)


class RunModel(NamedTuple):
    """A scenario compiled once per run (frozen model; each run makes its buffers).  mpk_c, spk_c: the
    controller's packed params; nodes, weights: Gauss-Legendre on [0, 1]; gains: packed + [e2_sign,
    null_space_scale]; spec: packed sub-task; F (4,) N; traj (5,): x_d (40); s0 (16,): state at t = 0."""

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
    try:
        s0 = initial_state(scn)  # both arms at rest
    except InitialStateError as exc:
        raise SimulationError(str(exc)) from None
    nodes, weights = gauss_legendre01(scn.slave.n_quad)
    F = np.array([*scn.interaction_forces[0], *scn.interaction_forces[1]], dtype=float)
    return RunModel(
        mpk_c=master_model.packed(scn.master), spk_c=scn.slave.packed(), nodes=nodes, weights=weights,
        gains=np.concatenate([scn.gains.packed(), [float(scn.faults.e2_sign), scn.faults.null_space_scale]]),
        spec=pack_subtask(scn.subtask, scn.slave), F=F, traj=trajectory_params(scn), s0=s0)


def run_meta(scn: Scenario, wall: float) -> dict:
    lo, hi = scn.slave.length_range
    return {
        "plant": scn.plant.kind, "wall_time": wall, "control_dt": scn.control_dt,
        "master_lengths": scn.plant_master.lengths, "length_range": (lo.tolist(), hi.tolist()),
        "max_bend": scn.slave.max_bend, "backbone_fn": partial(slave_model.backbone, scn.slave),  # picklable
        "master_base": (0.0, 0.0, 0.0), "slave_base": (0.0, 0.0, 0.0), "mujoco_warnings": 0,
        "environment": [dataclasses.asdict(o) for o in scn.environment.objects],  # drawn by the outputs
    }
