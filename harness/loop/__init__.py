"""The closed loop: the paper's controllers (on the nominal analytic models) driving a plant.

`simulate(scn, plant=None)` is the one entry point: it takes a scenario and a plant
(`harness.plant.build_plant(scn)` when not given) and returns the in-memory `Trajectory`.  The
plant-specific loops are `harness.loop.analytic_loop`, `harness.loop.mujoco_loop` and
`harness.loop.stepped_loop` (plants stepped from Python, e.g. the Cosserat rod); what they
share (initial state, noise, status codes, stop flag) is `harness.loop.common`; the compiled
kernels are `harness.loop.kernels` / `harness.loop.mujoco_kernels`, compiled by `harness.loop.fast`.
The loop knows nothing of files, recordings or sweeps.
"""

from __future__ import annotations

from typing import Any


def simulate(scn, plant: Any = None, progress: bool = False):
    """Run one scenario on `plant` (default: the plant `scn.plant` describes); returns the Trajectory.

    A run that diverges or is interrupted (`harness.loop.common.STOP`) returns everything up to that
    point, with `status` and `message` saying what happened and when."""
    if plant is None:
        from harness.plant import build_plant

        plant = build_plant(scn)
    if hasattr(plant, "advance"):  # a stepped plant (harness.plant.stepped.SteppedPlant)
        from harness.loop.stepped_loop import simulate_stepped

        return simulate_stepped(scn, plant, progress=progress)
    if plant.kind == "analytic":
        from harness.loop.analytic_loop import simulate_analytic

        return simulate_analytic(scn, progress=progress, plant=plant)
    from harness.loop.mujoco_loop import simulate_mujoco

    return simulate_mujoco(scn, progress=progress, plant=plant)
