"""Ahead-of-time compiled loop entry kernels: a run that never loads numba.

Why.  Loading numba costs every process about 1.2-1.5 s before its first step on the reference
machine (`benchmarks/bench_core.py`): importing numba and llvmlite (~0.4 s), then, at the first call
of any kernel, even one loaded from numba's on-disk cache, initialising its CPU target: some 250
implementation modules, one of which imports SciPy's linear algebra (~0.6-0.9 s).  For the 20-s paper
run that is as long as the loop itself, and a sweep pays it again in every worker.

What.  The loop's entry kernels, called once per chunk of steps (`ENTRIES`), are compiled once with
`numba.pycc` into a CPython extension module in the kernel cache; every later process imports that
module (milliseconds) and calls it like the jitted kernel, without importing numba.  The module is
compiled from the very function the JIT compiles (`harness.loop.fast`, callees compiled by numba and
linked in), for the exact argument types of the call, so the numbers are the same (tested
bit-identical).  Its Python wrapper releases the GIL like `njit(nogil=True)`, so a sweep's threads
still run side by side.

Where.  One module per entry and argument types:
`<cache root>/aot-<digest>-<recipe>/octarm_<entry>_<types>.so` (`harness.loop.fast.cache_root`; the
digest covers the kernel sources, numba, numpy and Python, the recipe this module's build and the
processor, `aot_dir`).
The argument types are read in pure Python (dtype, ndim, layout, writeable, nested tuples: what
`numba.typeof` looks at), so finding the module needs no numba.  A missing module is built on
first use (about 20-60 s, one line on stderr), under a file lock so that sweep workers build it once.

Fallback.  If the module cannot be built or loaded (no C compiler, a numba without pycc, ...), the
jitted kernel runs instead (same numbers, numba's start-up cost) and the reason is written next to
the module (`<module>.failed`, so later runs do not retry; delete it to retry) and logged once.
TELEOP_NO_AOT=1: always the jitted kernels.  TELEOP_NO_JIT=1: interpreted kernels (`fast.kernels`).
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import logging
import os
import sys
import sysconfig
import tempfile
import threading
import warnings
from pathlib import Path

import numpy as np

from harness.config.runtime import options
from harness.loop import fast

log = logging.getLogger(__name__)

# Kernels called once per chunk of steps (not per step: finding the module costs ~50 us per call).
ENTRIES = ("mujoco_chunk", "analytic_chunk", "backbone_world", "kinematics_replay")


class Unsupported(TypeError):
    """An argument whose numba type this module does not derive (the jitted kernel runs instead)."""


def type_key(a) -> str:
    """A string that determines `numba.typeof(a)` for the argument types the loops pass: arrays
    (dtype, ndim, layout C/F/A, writeable; numba's typeof does not look at alignment), bool, int,
    float, numpy scalars, nested tuples.
    Raises Unsupported for anything else."""
    if isinstance(a, np.ndarray):
        if a.dtype.fields is not None or a.dtype.hasobject:  # dtype.str would not tell records apart
            raise Unsupported(f"array of dtype {a.dtype}")
        f = a.flags
        layout = "C" if f.c_contiguous else ("F" if f.f_contiguous else "A")
        return f"a{a.dtype.str}{a.ndim}{layout}{'w' if f.writeable else 'r'}"
    if isinstance(a, (bool, np.bool_)):
        return "b"
    if isinstance(a, np.generic):
        return "s" + a.dtype.str
    if isinstance(a, int):
        if not -(2 ** 63) <= a < 2 ** 63:
            raise Unsupported(f"integer {a} outside int64")
        return "i"
    if isinstance(a, float):
        return "f"
    if isinstance(a, tuple):
        return "(" + ",".join(type_key(x) for x in a) + ")"
    raise Unsupported(f"argument of type {type(a).__name__}")


def aot_dir() -> Path:
    """Folder of the compiled entry modules for the current kernel sources and versions (and this
    module's build recipe)."""
    return fast.cache_root() / f"aot-{fast.source_digest()}-{_recipe()}"


@functools.cache
def _recipe() -> str:
    import hashlib
    import inspect

    return hashlib.sha256((inspect.getsource(sys.modules[__name__]) + _cpu_id()).encode()).hexdigest()[:8]


def _cpu_id() -> str:
    """The processor's model and instruction-set flags: a cache folder shared by different machines (a
    network home) never hands one machine's module to another (numba links its jitted callees, compiled
    for the host processor, into the module)."""
    import platform

    lines = []
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith(("model name", "flags", "Features", "CPU part")):
                    lines.append(line)
                elif not line.strip() and lines:  # the first processor's block is enough
                    break
    except OSError:
        pass
    return "".join(lines) or f"{platform.machine()} {platform.processor()}"


def module_name(entry: str, key: str) -> str:
    import hashlib

    return f"octarm_{entry}_{hashlib.sha256(key.encode()).hexdigest()[:16]}"


def _load(modname: str, path: Path):
    spec = importlib.util.spec_from_file_location(modname, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@contextlib.contextmanager
def _locked(path: Path):
    import fcntl

    with open(path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@contextlib.contextmanager
def _wrapper_releases_gil():
    """numba.pycc compiles its Python wrappers with default flags; ask for the wrapper `njit(nogil=True)`
    builds (`Flags.release_gil`: the GIL is released around the native call)."""
    import numba.pycc.compiler as pcc

    base = pcc.Flags

    class _Flags(base):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            self.release_gil = True

    pcc.Flags = _Flags
    try:
        yield
    finally:
        pcc.Flags = base


def toolchain_problem() -> str | None:
    """Why no module can be built here (no C compiler, no Python headers), or None: checked before
    numba spends its 20-60 s compiling a module that could not be linked."""
    import shutil

    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(cc) is None:
        return f"no C compiler ({cc!r} not found; set CC)"
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists():
        return "no Python headers (Python.h; install the Python development package)"
    return None


def build(entry: str, args: tuple, modname: str, path: Path) -> None:
    """Compile `entry` for the types of `args` into the extension module file `path` (atomic; needs the
    C toolchain, `toolchain_problem`)."""
    import numba

    disp = getattr(fast.kernels(True), entry)
    argtypes = tuple(numba.typeof(a) for a in args)
    disp.compile(argtypes)  # from numba's cache when present; gives the return type
    sig = disp.overloads[argtypes].signature
    with tempfile.TemporaryDirectory(prefix=f".{modname}-", dir=path.parent) as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
            from numba.pycc import CC

            cc = CC(modname)
            cc.output_dir = tmp
            cc.verbose = False
            cc.export(entry, sig)(disp.py_func)
            with _wrapper_releases_gil(), contextlib.redirect_stdout(sys.stderr):
                cc.compile()
        built = Path(tmp) / (modname + sysconfig.get_config_var("EXT_SUFFIX"))
        os.replace(built, path)


# Held while an entry resolves its module: importing one extension module from two threads at once fails
# inside importlib (measured: "TypeError: can only concatenate str (not "NoneType") to str").
_RESOLVING = threading.RLock()


class Entry:
    """Callable standing for the kernel `name`: the AOT module for the call's argument types, else the
    jitted (or, with TELEOP_NO_JIT=1, interpreted) kernel."""

    def __init__(self, name: str):
        self.name = name
        self._fns: dict[str, object] = {}

    def __call__(self, *args):
        try:
            key = type_key(args)
        except Unsupported:
            return getattr(fast.K, self.name)(*args)
        fn = self._fns.get(key)
        if fn is None:
            with _RESOLVING:  # threads of one process (a sweep's thread executor) load each module once
                fn = self._fns.get(key)
                if fn is None:
                    fn = self._fns[key] = self._resolve(key, args)
        return fn(*args)

    def _resolve(self, key: str, args: tuple):
        opts = options()
        if not opts.jit or not opts.aot:
            return getattr(fast.K, self.name)
        modname = module_name(self.name, key)
        try:
            folder = aot_dir()
            path = folder / (modname + sysconfig.get_config_var("EXT_SUFFIX"))
            failed = path.with_name(modname + ".failed")
            if not path.exists() and not failed.exists():
                folder.mkdir(parents=True, exist_ok=True)
                with _locked(folder / f".{modname}.lock"):
                    if not path.exists() and not failed.exists():  # not built meanwhile by another process
                        self._build(args, modname, path, failed)
            if path.exists():
                return getattr(_load(modname, path), self.name)
            reason = failed.read_text().strip() if failed.exists() else "not built"
        except Exception as e:  # noqa: BLE001 - unreadable cache, failed import: the JIT runs instead
            reason = f"{type(e).__name__}: {e}"
        log.warning("ahead-of-time kernel %s unavailable (%s); using the jitted kernel", self.name, reason)
        return getattr(fast.K, self.name)


    def _build(self, args: tuple, modname: str, path: Path, failed: Path) -> None:
        """Build the module, or record in `failed` why it cannot be (then the jitted kernel runs)."""
        problem = toolchain_problem()
        if problem is None:
            print(f"teleop: compiling the loop kernel {self.name} ahead of time into {path.parent} "
                  "(once per code version, about 20-60 s)", file=sys.stderr, flush=True)
            try:
                build(self.name, args, modname, path)
                return
            except Exception as e:  # noqa: BLE001 - any build failure: the JIT runs instead
                problem = f"{type(e).__name__}: {e}"
        failed.write_text(problem + "\n")


class _Entries:
    def __init__(self):
        self._entries: dict[str, Entry] = {}

    def __getattr__(self, name: str) -> Entry:
        if name not in ENTRIES:
            raise AttributeError(f"{name!r} is not an ahead-of-time entry kernel; ENTRIES: {ENTRIES}")
        entry = self._entries.get(name)
        if entry is None:  # setdefault: two threads asking at once get the same Entry
            entry = self._entries.setdefault(name, Entry(name))
        return entry


A = _Entries()  # A.mujoco_chunk(...): like fast.K.mujoco_chunk(...), without loading numba when built


def forget() -> None:
    """Forget the kernels resolved so far in this process (the next call resolves again: reads
    TELEOP_NO_AOT / TELEOP_CACHE_DIR anew)."""
    A._entries.clear()


__all__ = ["A", "ENTRIES", "Entry", "Unsupported", "aot_dir", "build", "forget", "module_name", "type_key"]
