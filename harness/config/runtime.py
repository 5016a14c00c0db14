"""Process-level settings shared by the `teleop` command and the sweep's pool workers: the garbage
collector's thresholds, the fast end of a process and the progress bars.  Nothing
here knows of plants or runs."""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import os
import sys
from typing import NoReturn

# Python's garbage collector in a command's or worker's process: a run imports hundreds of thousands
# of long-lived objects (numba, MuJoCo, Rerun, matplotlib) and each full collection traverses all of
# them.  With the default thresholds (700, 10, 10) a `teleop run` spent 0.46-0.51 s in 3 full and ~490
# young collections; with these, 0.13-0.18 s in ~34 young ones (benchmarks/RESULTS.md).  Reference
# cycles are still collected, just in larger batches.
GC_THRESHOLDS = (10_000, 50, 50)


def set_gc_thresholds() -> None:
    """Apply GC_THRESHOLDS to this process."""
    gc.set_threshold(*GC_THRESHOLDS)


def end_process(rc: int) -> NoReturn:
    """Flush stdout/stderr and end the process with `os._exit(rc)`, skipping the interpreter's module
    teardown and final garbage collection: with numba, MuJoCo, Rerun and matplotlib loaded that teardown
    takes about 1 s and writes nothing (benchmarks/RESULTS.md).  Callers make sure every file they
    wrote is complete and closed first."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(rc)


def fast_exit(rc: int) -> NoReturn:
    """Run the atexit handlers (Rerun's shutdown, multiprocessing, logging), then `end_process(rc)`."""
    try:
        atexit._run_exitfuncs()  # CPython's own exit step (the module has had it since Python 2)
    finally:
        end_process(rc)


@functools.cache
def progress_bar_class() -> type:
    """tqdm's bar without its monitor thread.  tqdm starts a daemon thread ("tqdm_monitor") at the first bar
    of a process, a disabled bar included, and leaves it running.  A process running any thread besides
    the main one must not fork, so the sweep then starts its workers as fresh interpreters
    (`harness.studies.executor.start_method`): measured, every sweep after the first in a process, and a
    sweep after a run, lost the forked start-up.  The monitor only adjusts `miniters` of bars that
    stall; these bars update every case or chunk.  ImportError when tqdm is missing."""
    from tqdm import tqdm

    class Bar(tqdm):
        monitor_interval = 0  # tqdm.__new__ starts the monitor only for a class with an interval

    return Bar


__all__ = ["GC_THRESHOLDS", "end_process", "fast_exit", "progress_bar_class", "set_gc_thresholds"]
