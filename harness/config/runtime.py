"""Process-level settings shared by the `teleop` command and the sweep's pool workers: the runtime options
(`RuntimeOptions`, from the TELEOP_* environment variables), the garbage collector's thresholds, the fast
end of a process and the progress bars.  Nothing here knows of plants or runs."""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import functools
import gc
import os
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NoReturn


@dataclasses.dataclass(frozen=True)
class RuntimeOptions:
    """How this process runs the kernels and reports failures (not what it simulates).

    cache_dir: root of the compiled-kernel cache ($TELEOP_CACHE_DIR, else $XDG_CACHE_HOME/octarm-teleop,
    else ~/.cache/octarm-teleop); jit: compile the kernels with numba (False: TELEOP_NO_JIT=1, the
    interpreted kernels, same maths, slow); aot: use the ahead-of-time loop modules (False: TELEOP_NO_AOT=1,
    numba's JIT); debug: print tracebacks of output-writing failures (TELEOP_DEBUG=1)."""

    cache_dir: Path
    jit: bool = True
    aot: bool = True
    debug: bool = False

    @classmethod
    def from_env(cls, env: Mapping[str, str] = os.environ) -> RuntimeOptions:
        root = env.get("TELEOP_CACHE_DIR") or os.path.join(
            env.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "octarm-teleop")
        return cls(cache_dir=Path(root), jit=env.get("TELEOP_NO_JIT", "0") != "1",
                   aot=env.get("TELEOP_NO_AOT", "0") != "1", debug=bool(env.get("TELEOP_DEBUG")))


_OPTIONS: list[RuntimeOptions] = []  # set by `using_options` (the `teleop` command: read once at its start)


def options() -> RuntimeOptions:
    """The options in force: those `using_options` set, else read from the environment now."""
    return _OPTIONS[-1] if _OPTIONS else RuntimeOptions.from_env()


@contextlib.contextmanager
def using_options(opts: RuntimeOptions) -> Iterator[RuntimeOptions]:
    """Run the block with `opts` as the process' runtime options (`options()`)."""
    _OPTIONS.append(opts)
    try:
        yield opts
    finally:
        _OPTIONS.remove(opts)

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


__all__ = ["GC_THRESHOLDS", "RuntimeOptions", "end_process", "fast_exit", "options", "progress_bar_class",
           "set_gc_thresholds", "using_options"]
