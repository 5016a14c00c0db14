"""Closed loop on the analytic plant (its own parameters), integrated with RK4 inside one compiled kernel
(`harness.loop.kernels.analytic_chunk`)."""

from __future__ import annotations

import numpy as np

from controllers import master as master_model
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import CHUNK, ChunkRun, RunModel, compile_model, noise_table, progress_bar
from harness.loop.trajectory import ROW_SLICES, ROW_WIDTH, Trajectory
from harness.plant.analytic import AnalyticPlant


def simulate_analytic(scn: Scenario, progress: bool = False, plant: AnalyticPlant | None = None,
                      on_chunk=None, model: RunModel | None = None) -> Trajectory:
    """The paper's law on the analytic plant.  plant: its parameters (default: the scenario's plant side);
    on_chunk: optional callable receiving each finished chunk of steps as a `Trajectory`; model: the
    scenario's `RunModel` (default: compiled here)."""
    if plant is None:
        plant = AnalyticPlant(scn.plant_master, scn.plant_slave)
    n = scn.n_steps
    a = model if model is not None else compile_model(scn)
    state = a.s0.copy()
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    Fc = np.zeros(4) if scn.sensing.force.mode == "ignored" else a.F  # the plant feels a.F
    rows[:, ROW_SLICES["F_true"]] = a.F
    rows[:, ROW_SLICES["F_sensed"]] = Fc
    plant_args = (a, Fc, scn.control_dt, max(1, scn.substeps), scn.continuous_control,
                  master_model.packed(plant.master), plant.slave.packed(), np.empty((4, 16)), np.empty(16))
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 8))  # [T1, T2] per slot of the actuation-delay ring
    data = (state, noise, scale, rows, cmdbuf, delay, scn.control_dt)
    run = ChunkRun(scn, rows, CHUNK, progress_bar(progress, n, "analytic plant"), on_chunk)
    run.run(lambda k, k1: A.analytic_chunk(k, k1, a, data, plant_args))
    return run.trajectory()
