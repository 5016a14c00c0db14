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
import threading

# the writers' modules, heaviest last (the recording's Rerun import is needed first)
OUTPUT_MODULES = ("harness.output.record", "harness.output.plots")


def _import_all(names: tuple[str, ...]) -> None:
    for name in names:
        with contextlib.suppress(Exception):
            importlib.import_module(name)


def prefetch_output_imports(names: tuple[str, ...] = OUTPUT_MODULES) -> threading.Thread:
    """Start (and return) a daemon thread importing `names`; join it before forking a writer, so that
    no import lock is held by a thread that does not exist in the child."""
    th = threading.Thread(target=_import_all, args=(names,), name="output-import-prefetch", daemon=True)
    th.start()
    return th


__all__ = ["OUTPUT_MODULES", "prefetch_output_imports"]
