"""MuJoCo's warning text, captured per run, also when several runs share the process.

MuJoCo has one process-wide warning callback (`mujoco.set_mju_user_warning`).  A run that set its own
callback would collect the warnings of every other run stepping at the same time (a sweep's thread
executor, `harness.studies.executor`), and the first run to finish would switch the capture off for the
others.  Here one dispatcher is installed while any run captures, and it hands each warning to the run
whose thread raised it (MuJoCo calls the callback in the thread that steps).

The warning *counts* never needed this: they live in each run's own `MjData` (`d.warning`).
"""

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
    else:  # a thread that runs no loop (user code stepping MuJoCo during a sweep): as MuJoCo's default
        sys.stderr.write(f"WARNING: {msg}\n")


class WarningSink:
    """The warning text MuJoCo raises in this thread until `close`.
    `text`: list of messages, in order.  Use as a context manager, or call `close` in a `finally`."""

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
