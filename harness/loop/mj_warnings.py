"""MuJoCo's warning text captured per run, also for runs sharing the process (a sweep's threads): one
process-wide callback hands each warning to the run whose thread raised it (counts: each run's `MjData`)."""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Iterator

import mujoco

_lock = threading.Lock()
_sinks: dict[int, list[str]] = {}  # thread ident -> the text list of the run that thread steps for


def _dispatch(msg) -> None:
    sink = _sinks.get(threading.get_ident())
    if sink is not None:
        sink.append(str(msg))
    else:  # a thread that runs no loop: as MuJoCo's default
        sys.stderr.write(f"WARNING: {msg}\n")


@contextlib.contextmanager
def warning_sink() -> Iterator[list[str]]:
    """The warning text MuJoCo raises in this thread inside the block (a list, in order)."""
    text: list[str] = []
    ident = threading.get_ident()
    with _lock:
        if not _sinks:
            mujoco.set_mju_user_warning(_dispatch)
        _sinks[ident] = text
    try:
        yield text
    finally:
        with _lock:
            if _sinks.get(ident) is text:
                del _sinks[ident]
            if not _sinks:
                mujoco.set_mju_user_warning(None)


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
