"""The protocol of plants stepped by `harness.loop.stepped_loop`; per control step: `true_state`,
`record(k)`, `command`, `advance(control_dt)`.  Optional: `record(k)` / `finish(traj, done)` (else
`slave_tip()` (2,) m and `geometry()` are copied each step), `forces(F (4,), contact (5,))`, `stop`,
`state_names`, `get_state(keep=False) -> (n,)`, `set_state(x)` (keep=True: `set_state` restores the
rest of the physics state).  Units: q1 rad, q2 = [d (m), k (1/m)], T1 N m, T2 [N, N m^2] (18)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class SteppedPlant(Protocol):
    """What `harness.loop.stepped_loop` needs from a plant (the optional members: see the module)."""

    kind: str  # as Scenario.plant.kind
    actuation: str  # "servo" | "torque" | "muscle"
    physics_dt: float  # s, the plant's own step; control_dt is a multiple of it

    def reset(self, state0: np.ndarray) -> None:
        """Both arms at rest at state0 (16,) = [q1, dq1, q2, dq2], commands cleared."""

    def command(self, T1: np.ndarray, T2: np.ndarray, q2_ref: np.ndarray, dq2_ref: np.ndarray,
                q2_sensed: np.ndarray) -> None:
        """Hold T1 (2,), T2 (6,), q2_ref (6,), dq2_ref (6,) until the next call; q2_sensed (6,): the
        sensed q2 they were computed from (maps of T2 that depend on q2)."""

    def advance(self, dt: float) -> int:
        """Advance by dt (a multiple of physics_dt); 0 or a status code."""

    def true_state(self, out: np.ndarray) -> int | None:
        """Noise-free [q1, dq1, q2, dq2] into out (16,); None/0 or a status code."""
