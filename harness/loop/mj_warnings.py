"""MuJoCo's warning text captured per run, also for runs sharing the process (a sweep's threads): one
process-wide callback hands each warning to the run whose thread raised it (counts: each run's `MjData`)."""

from __future__ import annotations

import sys
import threading

import mujoco

_lock = threading.Lock()
_sinks: dict[int, list[str]] = {}  # thread ident -> the text list of the run that thread steps for


def _dispatch(msg) -> None:
    sink = _sinks.get(threading.get_ident())
    if sink is not None:
        sink.append(str(msg))
    else:  # a thread that runs no loop: as MuJoCo's default
        sys.stderr.write(f"WARNING: {msg}\n")


class WarningSink:
    """The warning text (`text`, in order) MuJoCo raises in this thread until `close` (a context manager)."""

    def __init__(self) -> None:
        self.text: list[str] = []
        self._ident = threading.get_ident()
        with _lock:
            if not _sinks:
                mujoco.set_mju_user_warning(_dispatch)
            _sinks[self._ident] = self.text

    def close(self) -> None:
        with _lock:
            if _sinks.get(self._ident) is self.text:
                del _sinks[self._ident]
            if not _sinks:
                mujoco.set_mju_user_warning(None)

    def __enter__(self) -> WarningSink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def warning_counts(numbers) -> dict[str, int]:
    """Non-zero MuJoCo warning counters by name (numbers: mjData.warning.number)."""
    return {name: int(numbers[int(w)]) for name, w in mujoco.mjtWarning.__members__.items()
            if name != "mjNWARNING" and int(numbers[int(w)])}


def warning_detail(warned: dict[str, int], text: list[str]) -> str:
    """The status message's detail of a run's warnings: " (name: count, ...); MuJoCo says: <first text>"
    ("" without any)."""
    if not warned:
        return ""
    detail = " (" + ", ".join(f"{k}: {v}" for k, v in warned.items()) + ")"
    return detail + (f"; MuJoCo says: {text[0].strip()}" if text else "")
