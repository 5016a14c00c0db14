"""Named status codes of a run's step (kernels, plants' `advance` / `true_state`, the loop): 0 is a step
that went well; any other code ends the run as "diverged" with `Status(code).text` in its message.
Compiled kernels use the ST_* integers (numba reads module-level integers as constants)."""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    OK = 0
    NONFINITE = 1
    MASTER_SINGULAR = 2
    SLAVE_SINGULAR = 3
    RUNAWAY = 4
    SECTION_LENGTH = 5
    MUJOCO_STATE = 6
    MUJOCO_WARNING = 7
    PLANT_STATE = 8

    @property
    def text(self) -> str:
        return _TEXT[self]


_TEXT = {
    Status.OK: "ok",
    Status.NONFINITE: "non-finite state or command",
    Status.MASTER_SINGULAR: "master Jacobian J1 singular",
    Status.SLAVE_SINGULAR: "slave J2 J2^T singular",
    Status.RUNAWAY: "runaway tracking error (|e| > 1 m)",
    Status.SECTION_LENGTH: "slave section length <= 0",
    Status.MUJOCO_STATE: "non-finite or exploding MuJoCo state (|x| > 1e6)",
    Status.MUJOCO_WARNING: "MuJoCo warning",
    Status.PLANT_STATE: "non-finite or exploding plant state (|x| > 1e6)",
}

# the same codes as plain integers, for the compiled kernels
(ST_OK, ST_NONFINITE, ST_MASTER_SINGULAR, ST_SLAVE_SINGULAR, ST_RUNAWAY, ST_SECTION_LENGTH, ST_MUJOCO_STATE,
 ST_MUJOCO_WARNING, ST_PLANT_STATE) = (int(s) for s in Status)
