"""Compiled versions of the pure-numpy kernels of `controllers/` (and of the plant maps).

`controllers/` imports numpy only; its kernels are written in the numba-compatible subset.  Here
each kernel is cloned with a shared globals namespace in which every kernel name refers to its
compiled counterpart, then wrapped in `numba.njit(cache=True)`, so calls between kernels stay in
machine code.  The compiled functions give the same numbers as the interpreted ones (tested).

Working arrays (`controllers.scratch`) are blocks of the kernel's stack frame when compiled
(`harness.loop.native.scratch_intrinsics`, put into that namespace), so the kernels that never make a heap
array are compiled without numba's runtime (`_nrt=False`): no reference counting in the per-step code.  A
kernel that does allocate (a run-time size) is listed in its module's HEAP_KERNELS; one that allocates
without being listed fails to compile, loudly.

Usage: `from harness.loop.fast import K; K.slave_control_kernel(...)`.  `K` is built on first access.
If numba is unavailable (or TELEOP_NO_JIT=1), K holds the interpreted functions (slow, same maths).

On-disk cache: numba's own cache does not notice when a kernel in *another* file changes (a cached
caller keeps the old callee), so the cache directory is keyed by a hash of every kernel module's
source (and of this module, which sets how they compile) and the numba/numpy versions: any code change
compiles afresh, never runs stale code.
Location: $TELEOP_CACHE_DIR, else $XDG_CACHE_HOME/octarm-teleop, else ~/.cache/octarm-teleop.
"""

from __future__ import annotations

import hashlib
import inspect
import threading
import types
from functools import cache
from pathlib import Path

from controllers import cc, control, master, moments, slave, subtasks, tip
from harness.config.runtime import options

MODULES = [cc, tip, moments, slave, master, subtasks, control]


def _extra_modules():
    """Kernel modules of harness/ (plant maps, analytic plant, loops), compiled the same way."""
    from harness.loop import force_kernels, kernels, native, stepped_kernels
    from harness.plant import analytic

    try:
        from harness.loop import mujoco_kernels
        from harness.plant import chain_map
    except ImportError:  # pragma: no cover - mujoco missing: its kernels are unavailable
        return [analytic, kernels, force_kernels, native, stepped_kernels]
    return [chain_map, analytic, kernels, force_kernels, native, mujoco_kernels, stepped_kernels]


def cache_root() -> Path:
    """Root folder of the compiled kernels: $TELEOP_CACHE_DIR, else $XDG_CACHE_HOME/octarm-teleop, else
    ~/.cache/octarm-teleop."""
    return options().cache_dir


@cache
def source_digest() -> str:
    """16 hex digits of a hash of every kernel module's source and the numba, numpy and Python versions
    (read without importing numba): the cache folders' key, so a code change never runs stale code."""
    import sys
    from importlib.metadata import PackageNotFoundError, version

    import numpy

    try:
        nb = version("numba")
    except PackageNotFoundError:  # pragma: no cover - numba missing: nothing is compiled
        nb = "none"
    h = hashlib.sha256(f"{nb} {numpy.__version__} {sys.version} {sys.platform}".encode())
    for mod in [*MODULES, *_extra_modules(), sys.modules[__name__]]:  # this module: how they are compiled
        h.update(inspect.getsource(mod).encode())
    return h.hexdigest()[:16]


def jit_wanted() -> bool:
    """Whether the kernels are compiled: False when TELEOP_NO_JIT=1 (the interpreted kernels)."""
    return options().jit


_BUILDING = threading.Lock()
_NAMESPACES: dict[bool | None, types.SimpleNamespace] = {}  # jit (None: as TELEOP_NO_JIT says) -> namespace


def kernels(jit: bool | None = None) -> types.SimpleNamespace:
    """Namespace of kernels, compiled with numba unless jit is False (or TELEOP_NO_JIT=1, read at the first
    call).  One per process and kind: `kernels()` and `kernels(True)` are the same namespace when the kernels
    are compiled.  Built under a lock: threads asking at once (a sweep's thread executor) wait for the one
    namespace (without the lock each built its own, and could compile before numba's extensions were
    registered).  Once built, a call is a dict lookup (`K.name` in the Python-stepped loop's steps)."""
    ns = _NAMESPACES.get(jit)
    if ns is None:
        with _BUILDING:
            ns = _NAMESPACES.get(jit)
            if ns is None:
                kind = jit_wanted() if jit is None else jit
                ns = _NAMESPACES.get(kind)
                if ns is None:
                    ns = _build(kind)
                _NAMESPACES[kind] = _NAMESPACES[jit] = ns
    return ns


def _build(jit: bool) -> types.SimpleNamespace:
    mods = MODULES + _extra_modules()
    names: dict[str, object] = {}
    for mod in mods:
        for name in mod.KERNELS:
            if name in names:
                raise RuntimeError(f"kernel name {name!r} defined twice")
            names[name] = getattr(mod, name)
    if not jit:
        return types.SimpleNamespace(**names)
    import numba

    for mod in mods:
        register = getattr(mod, "register_numba_extensions", None)
        if register is not None:
            register()
    numba.config.CACHE_DIR = str(cache_root() / ("numba-" + source_digest()))

    ns: dict[str, object] = {}
    for mod in mods:
        ns.update({k: v for k, v in vars(mod).items() if not k.startswith("__")})
    from harness.loop.native import scratch_intrinsics

    ns.update(scratch_intrinsics())  # controllers.scratch's arrays on the kernels' stack frames
    nocache = set()
    for mod in mods:
        nocache.update(getattr(mod, "NOCACHE", ()))
    heap = set()  # kernels that allocate numpy arrays on the heap: compiled with numba's runtime
    for mod in mods:
        heap.update(getattr(mod, "HEAP_KERNELS", ()))
    compiled = {}
    for name, f in names.items():
        clone = types.FunctionType(f.__code__, ns, name, f.__defaults__, f.__closure__)
        clone.__module__ = f.__module__
        clone.__qualname__ = f.__qualname__
        compiled[name] = numba.njit(cache=name not in nocache, nogil=True, _nrt=name in heap)(clone)
    ns.update(compiled)
    return types.SimpleNamespace(**compiled)


class _Lazy:
    """`K.name`: the kernel `name` of `kernels()`, built at the first access.  Each kernel is kept as an
    attribute after its first access, so that later ones (the Python-stepped loop's per-step calls) are
    plain attribute lookups, not `__getattr__` (measured 0.85 us per access)."""

    def __getattr__(self, item):
        fn = getattr(kernels(), item)
        self.__dict__[item] = fn
        return fn


K = _Lazy()
