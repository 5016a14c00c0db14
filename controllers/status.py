"""Named status codes of a run's step (kernels, plants' `advance` / `true_state`, the loop): 0 is a step
that went well; any other code ends the run as "diverged" with `Status(code).text` in its message.
Compiled kernels use the ST_* integers (numba reads module-level integers as constants)."""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    """A status code and its one-line `text`."""

    OK = 0, "ok"
    NONFINITE = 1, "non-finite state or command"
    MASTER_SINGULAR = 2, "master Jacobian J1 singular"
    SLAVE_SINGULAR = 3, "slave J2 J2^T singular"
    RUNAWAY = 4, "runaway tracking error (|e| > 1 m)"
    SECTION_LENGTH = 5, "slave section length <= 0"
    MUJOCO_STATE = 6, "non-finite or exploding MuJoCo state (|x| > 1e6)"
    MUJOCO_WARNING = 7, "MuJoCo warning"
    PLANT_STATE = 8, "non-finite or exploding plant state (|x| > 1e6)"

    def __new__(cls, value: int, text: str) -> Status:
        member = int.__new__(cls, value)
        member._value_ = value
        member.text = text
        return member


# the same codes as plain integers, for the compiled kernels
(ST_OK, ST_NONFINITE, ST_MASTER_SINGULAR, ST_SLAVE_SINGULAR, ST_RUNAWAY, ST_SECTION_LENGTH, ST_MUJOCO_STATE,
 ST_MUJOCO_WARNING, ST_PLANT_STATE) = (int(s) for s in Status)
