"""The closed loop: a controller (on the nominal analytic models) driving a plant.  `simulate(scn)` runs the
paper's law on the analytic and MuJoCo plants in compiled loops, anything else in the Python-level loop
(`stepped_loop`)."""

from __future__ import annotations

from typing import Any


def releases_gil(scn) -> bool:
    """Whether `simulate(scn)` runs in a compiled loop releasing the GIL (scales over a sweep's threads)."""
    from harness.config.runtime import options

    return scn.controller.name == "paper" and scn.plant.kind in ("mujoco", "analytic") and options().jit


def simulate(scn, plant: Any = None, progress: bool = False, on_chunk=None):
    """Run one scenario on `plant` (default: `scn.plant`'s); returns the Trajectory, up to the step where a
    run diverged or was interrupted (`status`, `message`).  on_chunk: optional callable receiving each
    finished chunk of steps as a `Trajectory` (a live viewer)."""
    from harness.loop.common import compile_model
    from harness.loop.interface_adapter import is_compiled
    from harness.plant import build_plant

    model = compile_model(scn)
    plant = build_plant(scn) if plant is None else plant
    if not is_compiled(scn) or hasattr(plant, "advance"):  # the Python-level loop, on a SteppedPlant
        from harness.loop.stepped_loop import simulate_stepped
        from harness.loop.stepped_plants import stepped_plant

        return simulate_stepped(scn, stepped_plant(scn, model, plant), progress, on_chunk, model)
    if plant.kind == "analytic":
        from harness.loop.analytic_loop import simulate_analytic

        return simulate_analytic(scn, progress=progress, plant=plant, on_chunk=on_chunk, model=model)
    from harness.loop.mujoco_loop import simulate_mujoco

    return simulate_mujoco(scn, progress=progress, plant=plant, on_chunk=on_chunk, model=model)
