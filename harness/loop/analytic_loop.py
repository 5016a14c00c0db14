"""Closed loop on the analytic plant: the controllers drive the analytic model itself (plant
parameters may differ from the controller's nominal ones), integrated with RK4 inside one compiled
kernel (`harness.loop.kernels.analytic_chunk`).  Returns the in-memory `Trajectory`.
"""

from __future__ import annotations

import time

import numpy as np

from controllers import master as master_model
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import (
    CHUNK,
    ChunkRun,
    RunModel,
    compile_model,
    noise_table,
    progress_bar,
    run_meta,
    set_outcome,
)
from harness.loop.trajectory import ROW_SLICES, ROW_WIDTH, Trajectory
from harness.plant.analytic import AnalyticPlant


def simulate_analytic(scn: Scenario, progress: bool = False,
                      plant: AnalyticPlant | None = None, on_chunk=None,
                      model: RunModel | None = None) -> Trajectory:
    """Closed loop on the analytic plant (plant params may differ from the controller's).
    plant: the plant's parameters (default: the scenario's plant side); on_chunk: optional callable
    receiving each finished chunk of steps as a `Trajectory` (e.g. a live viewer); model: the scenario's
    `RunModel` (default: compiled here)."""
    if plant is None:
        plant = AnalyticPlant(scn.plant_master, scn.plant_slave)
    n = scn.n_steps
    a = model if model is not None else compile_model(scn)
    state = a.s0.copy()
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    # constant interaction forces: the plant feels a.F; the laws get them unless ignored
    Fc = np.zeros(4) if scn.sensing.force.mode == "ignored" else a.F
    rows[:, ROW_SLICES["F_true"]] = a.F
    rows[:, ROW_SLICES["F_sensed"]] = Fc
    mpk_p = master_model.packed(plant.master)
    spk_p = plant.slave.packed()
    nsub = max(1, scn.substeps)
    plant_args = (scn.control_dt, nsub, scn.continuous_control, mpk_p, spk_p)
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 8))  # [T1, T2] per slot of the actuation-delay ring
    bar = progress_bar(progress, n, "analytic plant")

    def part(k: int, done: int) -> None:
        piece = Trajectory.from_rows(rows[k:done])
        piece.meta.update(run_meta(scn, 0.0))
        on_chunk(piece)

    run = ChunkRun(n, CHUNK, bar, part if on_chunk is not None else None)
    t0 = time.perf_counter()
    error = ""
    try:
        run.run(lambda k, k1: A.analytic_chunk(k, k1, a, plant_args,
                                               (state, noise, scale, Fc, rows[k:k1], cmdbuf, delay)))
    except KeyboardInterrupt:
        run.interrupted = True
    except Exception as exc:  # keep what was computed; report the cause
        error = f"{type(exc).__name__}: {exc}"
    finally:
        if bar is not None:
            bar.close()
    status, done, interrupted = run.status, run.done, run.interrupted
    traj = Trajectory.from_rows(rows[:done])
    traj.meta.update(run_meta(scn, time.perf_counter() - t0))
    set_outcome(traj, status, interrupted, error)
    return traj
