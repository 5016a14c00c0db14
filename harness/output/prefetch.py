"""Import the output writers' libraries (Rerun with pyarrow, matplotlib with its font cache) in a
background thread while the simulation runs.

The compiled loops release the GIL (`numba.njit(nogil=True)`, `harness.loop.fast`), so on a machine
with a free core these imports (about 1.2-1.4 s on the reference machine, `benchmarks/bench_e2e.py`)
cost no wall time; with one core they cost what they would have cost later.  Nothing here changes
what is imported: only when.  A failing import is not reported here; the writer that needs the module
imports it again and reports the error as an output failure.
"""

from __future__ import annotations

import contextlib
import importlib
import sys
import threading

# the writers' modules, heaviest last (the recording's Rerun import is needed first)
OUTPUT_MODULES = ("harness.output.record", "harness.output.plots")


# While the imports run, a thread waiting for the GIL (the loop, back from a compiled call) asks for it
# after this many seconds instead of CPython's default 5 ms (`sys.setswitchinterval`; restored when the
# imports end).  It only matters when a thread waits, so the imports themselves are not slowed.
SWITCH_INTERVAL = 0.0005


def _import_all(names: tuple[str, ...]) -> None:
    for name in names:
        with contextlib.suppress(Exception):
            importlib.import_module(name)


def _run(names: tuple[str, ...], restore: float) -> None:
    try:
        _import_all(names)
    finally:
        if sys.getswitchinterval() == SWITCH_INTERVAL:  # unless someone else changed it meanwhile
            sys.setswitchinterval(restore)


def prefetch_output_imports(names: tuple[str, ...] = OUTPUT_MODULES) -> threading.Thread:
    """Start (and return) a daemon thread importing `names`; join it before forking a writer, so that
    no import lock is held by a thread that does not exist in the child."""
    restore = sys.getswitchinterval()
    if restore > SWITCH_INTERVAL:
        sys.setswitchinterval(SWITCH_INTERVAL)
    th = threading.Thread(target=_run, args=(names, restore), name="output-import-prefetch", daemon=True)
    th.start()
    return th


__all__ = ["OUTPUT_MODULES", "SWITCH_INTERVAL", "prefetch_output_imports"]
