"""The closed loop: a controller (on the nominal analytic models) driving a plant.

`simulate(scn, plant=None)` is the one entry point: it compiles the scenario once into a `RunModel`
(`harness.loop.common.compile_model`), takes a plant (`harness.plant.build_plant(scn)` when not given) and
returns the in-memory `Trajectory`.  The paper's law (registered as "paper") on the analytic and MuJoCo
plants runs in the compiled loops `harness.loop.analytic_loop` / `harness.loop.mujoco_loop`; every other
controller (`controllers.interface.Controller`) on any plant, and any controller on a plant stepped from
Python such as the Cosserat rod, runs in the one Python-level loop `harness.loop.stepped_loop` (plants:
`harness.loop.stepped_plants`).  What they share (the run model, noise, the chunk driver, the stop flag) is
`harness.loop.common`; the per-step glue (runaway and section-length checks, servo reference) and the
compiled kernels are `harness.loop.kernels` / `harness.loop.mujoco_kernels`, compiled by
`harness.loop.fast`.  Status codes: `controllers.status`.  The loop knows nothing of files, recordings or
sweeps.
"""

from __future__ import annotations

from typing import Any


def releases_gil(scn) -> bool:
    """Whether `simulate(scn)` runs in a compiled loop that releases the GIL while it steps: the paper's
    controller on the MuJoCo or analytic plant, with compiled kernels (not TELEOP_NO_JIT=1).  Such runs
    scale over the threads of one process (a sweep's thread executor, `harness.studies.executor`); the
    Python-stepped loop (Python controllers, the Cosserat rod) holds the GIL for most of each step."""
    if scn.controller.name != "paper" or scn.plant.kind not in ("mujoco", "analytic"):
        return False
    from harness.loop.fast import jit_wanted

    return jit_wanted()


def simulate(scn, plant: Any = None, progress: bool = False, on_chunk=None):
    """Run one scenario on `plant` (default: the plant `scn.plant` describes); returns the Trajectory.
    on_chunk: optional callable receiving each finished chunk of control steps as a `Trajectory`
    (e.g. a live viewer, `harness.output.viewer.LiveView`).

    A run that diverges or is interrupted (`harness.loop.common.STOP`) returns everything up to that
    point, with `status` and `message` saying what happened and when."""
    from harness.loop.common import compile_model

    model = compile_model(scn)  # once per run: every loop, adapter and controller context reads it
    if plant is None:
        from harness.plant import build_plant

        plant = build_plant(scn)
    from harness.loop.interface_adapter import is_compiled

    python_ctrl = not is_compiled(scn)  # a controllers.interface.Controller, stepped from Python
    if python_ctrl or hasattr(plant, "advance"):  # the one Python-level loop, on a SteppedPlant
        from harness.loop.stepped_loop import simulate_stepped

        if not hasattr(plant, "advance"):  # the MuJoCo / analytic plant: its Python-stepped adapter
            from harness.loop.stepped_plants import stepped_plant

            plant = stepped_plant(scn, model, plant)
        return simulate_stepped(scn, plant, progress=progress, on_chunk=on_chunk, model=model)
    if plant.kind == "analytic":
        from harness.loop.analytic_loop import simulate_analytic

        return simulate_analytic(scn, progress=progress, plant=plant, on_chunk=on_chunk, model=model)
    from harness.loop.mujoco_loop import simulate_mujoco

    return simulate_mujoco(scn, progress=progress, plant=plant, on_chunk=on_chunk, model=model)
