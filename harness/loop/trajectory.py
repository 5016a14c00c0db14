"""In-memory result of one run (what loggers, plots, metrics and bounds checks consume).  All arrays share
the first axis: the n control steps completed (a run that stopped early has `status != "ok"`).
Task-space vectors are [X, Z] in metres, each relative to its own robot base."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np

# the per-step record row of the loops (`harness.loop.kernels.record_row`): name -> width
ROW_FIELDS: dict[str, int] = {
    "t": 1,
    "q1": 2, "dq1": 2, "q2": 6, "dq2": 6,  # true plant state (sensed, before noise)
    "xd": 2, "x1": 2, "x2": 2,  # x2 = analytic tip of the sensed q2
    "e1": 2, "e2": 2, "de1": 2, "de2": 2,
    "beta": 1, "ya": 1, "deN": 6, "T1": 2, "T2": 6, "u2": 6,
    # interaction (harness.loop.force_kernels): true and controller-side F = [F1x, F1z, F2x, F2z],
    # contact summary (CONTACT_INFO) and the operator's hand position
    "F_true": 4, "F_sensed": 4, "contact": 5, "hand": 2,
}
_ENDS = list(accumulate(ROW_FIELDS.values()))
ROW_SLICES: dict[str, slice] = {k: slice(e - w, e)
                                 for (k, w), e in zip(ROW_FIELDS.items(), _ENDS, strict=True)}
ROW_WIDTH = _ENDS[-1]


@dataclass
class Trajectory:
    """Time histories of one run.

    t: (n,) s | q1, dq1: (n, 2) rad, rad/s | q2, dq2: (n, 6) [d (m), k (1/m)] and rates
    xd, x1, x2: (n, 2) m | e1 = xd - x1, e2 = x1 - x2: (n, 2) m (eq. 11, 16), x2 analytic of sensed q2
    beta: (n,) manipulability (41) (the paper's Fig. 4) | ya: (n,) y_a = exp(-k_y beta_s) (29) of the
      controller's sub-task function beta_s (`controllers.subtasks`; != beta with the limits part on)
    deN: (n, 6) null-space velocity error (23)
    T1: (n, 2) N m | T2: (n, 6) generalized forces [N, N m^2] | u2: (n, 6) slave auxiliary input (18)
    F_true: (n, 4) N, interaction forces ON the robots at the tips [F1x, F1z, F2x, F2z] (operator at the
      master handle + constant; contact on the slave tip body + constant), world X/Z
    F_sensed: (n, 4) N, what the laws (13), (17) got (sensing.force.mode)
    contact: (n, 5) [contacts on the arm, arm net contact force X, Z (N, on the arm), min signed
      distance arm-objects (m, < 0 = penetration; 0 without contact), contacts on the tip body]
    hand: (n, 2) m, operator hand position (master task frame; 0 when no operator)
    x2_plant: (n, 2) m, MuJoCo tip site (None on the analytic plant)
    body_pos/body_quat: (n, nb, 3) / (n, nb, 4 wxyz) world poses of the plant's slave segment bodies
    master_pos: (n, 3, 3) world positions of master base, elbow, tip (None on the analytic plant)
    """

    t: np.ndarray
    q1: np.ndarray
    dq1: np.ndarray
    q2: np.ndarray
    dq2: np.ndarray
    xd: np.ndarray
    x1: np.ndarray
    x2: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    de1: np.ndarray
    de2: np.ndarray
    beta: np.ndarray
    ya: np.ndarray
    deN: np.ndarray
    T1: np.ndarray
    T2: np.ndarray
    u2: np.ndarray
    F_true: np.ndarray | None = None
    F_sensed: np.ndarray | None = None
    contact: np.ndarray | None = None
    hand: np.ndarray | None = None
    x2_plant: np.ndarray | None = None
    contact_points: np.ndarray | None = None  # (n, N_POINTS, 6) [pos xyz world, force on the arm xyz] N
    body_pos: np.ndarray | None = None
    body_quat: np.ndarray | None = None
    master_pos: np.ndarray | None = None
    status: str = "ok"  # "ok" | "diverged" | "interrupted" | "error"
    message: str = ""
    meta: dict = field(default_factory=dict)  # plant description for loggers (geometry, bases, ...)

    @classmethod
    def from_rows(cls, rows: np.ndarray, **extra) -> Trajectory:
        """From the (n, ROW_WIDTH) record of a loop (copies the data); extra: other fields."""
        kw = {k: np.array(rows[:, s], dtype=float) for k, s in ROW_SLICES.items()}
        return cls(**{k: v[:, 0] if ROW_FIELDS[k] == 1 else v for k, v in kw.items()}, **extra)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def e2_plant(self) -> np.ndarray | None:
        """Coordination error against the MuJoCo tip site: x1 - x2_plant, (n, 2) m."""
        return None if self.x2_plant is None else self.x1 - self.x2_plant
