"""The protocol of plants stepped from Python by the one Python-level loop (`harness.loop.stepped_loop`).

A stepped plant simulates both arms; the controller sees only its sensed state.  Implementations: the
Cosserat rod (`harness.plant.cosserat.plant`) and the MuJoCo and analytic adapters
(`harness.loop.stepped_plants`).  Per control step of length control_dt the loop (`Stepper.step`) calls
`true_state`, then (after the controller) `record(k)`, `command` (the commands of step k - actuation delay)
and `advance(control_dt)`.

Optional members:
* `record(k)` / `finish(traj, done)`: the plant keeps its recording geometry of step k and writes it into
  traj at the end; without them it gives `slave_tip()` (its own slave tip [X, Z] (2,), m) and `geometry()`
  (arrays such as "centreline" (n, 3), "sections" (4, 3), "master" (3, 3), world frame), copied each step;
* `forces(F (4,), contact (5,))`: the true interaction forces of the step (else the scenario's constant
  ones); `stop`: the run's stop flag, for plants with long inner loops;
* `state_names`, `get_state(keep=False) -> (n,)`, `set_state(x)`: the plant's state coordinates (the
  closed-loop map of `harness.studies.stability`); keep=True also keeps the rest of its physics state
  (e.g. MuJoCo's warm start and time), which every later `set_state` restores.

Units: q1 (rad), dq1 (rad/s), q2 = [d1, d2, d3 (m), k1, k2, k3 (1/m)] and rates; T1 (N m) master torques
(eq. 13); T2 = [T_d (N), T_k (N m^2)] slave generalized forces (eq. 18).  Servo plants track q2_ref /
dq2_ref and may add T2 as feed-forward; torque plants apply T2.  Statuses: `controllers.status.Status`.
"""

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
