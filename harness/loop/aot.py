"""Ahead-of-time compiled loop entry kernels (`ENTRIES`, a run that never loads numba): built with
`numba.pycc` for the call's argument types into `aot_dir()/octarm_<entry>_<types>.so` on first use.
Fallback: the jitted kernel, the reason in `<module>.failed` (delete it to retry).  TELEOP_NO_AOT=1: always
the jitted kernels."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import inspect
import logging
import os
import platform
import shutil
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

ENTRIES = ("mujoco_chunk", "analytic_chunk", "backbone_world", "kinematics_replay")


class Unsupported(TypeError):
    """An argument whose numba type this module does not derive (the jitted kernel runs instead)."""


def type_key(a) -> str:
    """A string that determines `numba.typeof(a)` (arrays, bool, int, float, numpy scalars, nested
    tuples); Unsupported for anything else."""
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
    """Folder of the entry modules of the kernel sources, versions, build recipe and processor."""
    return fast.cache_root() / f"aot-{fast.source_digest()}-{_recipe()}"


@functools.cache
def _recipe() -> str:
    return hashlib.sha256((inspect.getsource(sys.modules[__name__]) + _cpu_id()).encode()).hexdigest()[:8]


def _cpu_id() -> str:
    """The processor's model and flags (a cache shared by machines never hands one's module to another)."""
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


@contextlib.contextmanager
def _locked(path: Path):
    import fcntl

    with open(path, "a+") as fh:  # closing it releases the lock
        fcntl.flock(fh, fcntl.LOCK_EX)
        yield


@contextlib.contextmanager
def _wrapper_releases_gil():
    """pycc's Python wrappers release the GIL around the native call, as `njit(nogil=True)`."""
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
    """Why no module can be built here (no C compiler, no Python headers), or None."""
    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(cc) is None:
        return f"no C compiler ({cc!r} not found; set CC)"
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists():
        return "no Python headers (Python.h; install the Python development package)"
    return None


def build(entry: str, args: tuple, modname: str, path: Path) -> None:
    """Compile `entry` for the types of `args` into the extension module `path` (atomically)."""
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


_RESOLVING = threading.RLock()


class Entry:
    """The kernel `name`: the AOT module for the call's argument types, else the jitted kernel."""

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
            with _RESOLVING:
                fn = self._fns.get(key)
                if fn is None:
                    fn = self._fns[key] = self._resolve(key, args)
        return fn(*args)

    def _resolve(self, key: str, args: tuple):
        opts = options()
        if not opts.jit or not opts.aot:
            return getattr(fast.K, self.name)
        modname = f"octarm_{self.name}_{hashlib.sha256(key.encode()).hexdigest()[:16]}"
        try:
            folder = aot_dir()
            path = folder / (modname + sysconfig.get_config_var("EXT_SUFFIX"))
            failed = path.with_name(modname + ".failed")
            if not path.exists() and not failed.exists():
                folder.mkdir(parents=True, exist_ok=True)
                with _locked(folder / f".{modname}.lock"):
                    if not path.exists() and not failed.exists():  # not built meanwhile
                        self._build(args, modname, path, failed)
            if path.exists():
                spec = importlib.util.spec_from_file_location(modname, path)
                mod = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(mod)
                return getattr(mod, self.name)
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
        return self._entries.get(name) or self._entries.setdefault(name, Entry(name))  # one per name


A = _Entries()  # A.mujoco_chunk(...): like fast.K.mujoco_chunk(...), without loading numba when built


def forget() -> None:
    """Forget the modules resolved in this process (the next call reads TELEOP_NO_AOT / the cache anew)."""
    A._entries.clear()


__all__ = ["A", "ENTRIES", "Entry", "Unsupported", "aot_dir", "build", "forget", "type_key"]
