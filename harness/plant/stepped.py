"""The protocol of plants stepped from Python (`harness.loop.stepped_loop`, the one Python-level loop,
drives them with any controller: the paper's or a `controllers.interface.Controller`).

A stepped plant simulates both arms (master and slave) and is advanced one control step at a time by
the loop; the controller never sees it directly, only its sensed state.  Implementations: the Cosserat
rod (`harness.plant.cosserat.plant`, no `harness.loop` import) and the Python-stepped MuJoCo and
analytic plants (`harness.loop.stepped_plants`, which use the loops' compiled kernels).

Per control step of length control_dt, the loop calls, in this order:

    status = plant.true_state(state)         # noise-free [q1, dq1, q2, dq2] (16,) at time t; None/0 ok
    ... noise, controller, record ...
    plant.record(k)  or  slave_tip(), geometry()   # the recording's plant geometry at time t
    plant.command(T1, T2, q2_ref, dq2_ref, q2_sensed)   # held until the next call
    status = plant.advance(control_dt)       # 0, or a controllers.status.Status code
    ... at the end: plant.finish(traj, done) if the plant has `record` / `finish`

Units: q1 (rad), dq1 (rad/s), q2 = [d1, d2, d3 (m), k1, k2, k3 (1/m)] and its rates; T1 (N m) master
joint torques (paper eq. 13); T2 = [T_d (N), T_k (N m^2)] slave generalized forces (eq. 18); servo
plants track q2_ref / dq2_ref (the reference the loop integrates from the slave input u2, see
`harness.loop.stepped_loop`) and may add T2 as feed-forward; torque plants apply T2 (the MuJoCo plant
maps it to its motors at q2_sensed, the sensed q2 of the step that computed the command, as the
compiled loop does).  With an actuation delay the loop passes the commands of step k - delay.
Optional recording hooks (instead of the per-step `slave_tip` / `geometry` copies): `record(k)` stores
the step's plant state, `finish(traj, done)` writes x2_plant, master/body poses and meta.
Task-space points [X, Z] (m) are relative to each robot's own base.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class SteppedPlant(Protocol):
    """What `harness.loop.stepped_loop.simulate_stepped` needs from a plant."""

    kind: str  # plant kind, as in Scenario.plant.kind (e.g. "cosserat")
    actuation: str  # "servo" (tracks q2_ref, T2 feed-forward) | "torque" (applies T2)
    physics_dt: float  # s, the plant's own step; control_dt is a multiple of it

    def reset(self, state0: np.ndarray) -> None:
        """Both arms at rest at state0 (16,) = [q1, dq1, q2, dq2] (time 0, commands cleared)."""

    def command(self, T1: np.ndarray, T2: np.ndarray, q2_ref: np.ndarray, dq2_ref: np.ndarray,
                q2_sensed: np.ndarray) -> None:
        """Hold T1 (2,), T2 (6,), q2_ref (6,), dq2_ref (6,) until the next call; q2_sensed (6,) the
        sensed q2 the controller computed them from (for maps of T2 that depend on q2)."""

    def advance(self, dt: float) -> int:
        """Advance by dt (a multiple of physics_dt); 0 or a status code (harness.loop.common)."""

    def true_state(self, out: np.ndarray) -> int | None:
        """Noise-free [q1, dq1, q2, dq2] into out (16,); q2 by the plant's own sensing.  Returns None
        or 0, or a status code if the plant's own checks fail (the loop also checks finiteness)."""

    def slave_tip(self) -> np.ndarray:
        """The plant's own slave tip [X, Z] (2,), m, relative to the slave base (for e2_plant)."""

    def geometry(self) -> dict[str, np.ndarray]:
        """Arrays for the recording at the current time (e.g. "centreline" (n, 3) world points,
        "sections" (4, 3) section boundaries, "master" (3, 3) master base/elbow/tip)."""
