"""The kernels (KERNELS of `controllers/` and harness' kernel modules) compiled into one namespace with
`numba.njit(cache=True, nogil=True)` (only HEAP_KERNELS with numba's runtime): `K.name(...)`.
TELEOP_NO_JIT=1: the interpreted functions.  Cache: `cache_root()/numba-<source_digest()>`."""

from __future__ import annotations

import hashlib
import inspect
import threading
import types
from functools import cache
from pathlib import Path

from controllers import cc, control, master, moments, slave, subtasks, tip
from harness.config.runtime import options
from harness.loop import trajectory

MODULES = [cc, tip, moments, slave, master, subtasks, control]


def _extra_modules():
    """Kernel modules of harness/ (plant maps, analytic plant, loops)."""
    from harness.loop import force_kernels, kernels, mujoco_kernels, native
    from harness.plant import analytic, chain_map

    return [chain_map, analytic, kernels, force_kernels, native, mujoco_kernels]


def cache_root() -> Path:
    """Root folder of the compiled kernels: $TELEOP_CACHE_DIR, else $XDG_CACHE_HOME/octarm-teleop, else
    ~/.cache/octarm-teleop."""
    return options().cache_dir


@cache
def source_digest() -> str:
    """16 hex digits of a hash of the kernel sources and versions (without importing numba)."""
    import sys
    from importlib.metadata import version

    import numpy

    h = hashlib.sha256(f"{version('numba')} {numpy.__version__} {sys.version} {sys.platform}".encode())
    # + the record row's layout (compiled into the kernels) and this module (how they are compiled)
    for mod in [*MODULES, *_extra_modules(), trajectory, sys.modules[__name__]]:
        h.update(inspect.getsource(mod).encode())
    return h.hexdigest()[:16]


_BUILDING = threading.Lock()
_NAMESPACES: dict[bool, types.SimpleNamespace] = {}  # jit -> namespace


def kernels(jit: bool | None = None) -> types.SimpleNamespace:
    """Namespace of kernels, compiled unless jit is False (None: as TELEOP_NO_JIT says).  One per process and
    kind, built under a lock (threads asking at once get the same one)."""
    kind = options().jit if jit is None else jit
    with _BUILDING:
        if kind not in _NAMESPACES:
            _NAMESPACES[kind] = _build(kind)
        return _NAMESPACES[kind]


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

    from harness.loop.native import register_numba_extensions, scratch_intrinsics

    register_numba_extensions()
    numba.config.CACHE_DIR = str(cache_root() / ("numba-" + source_digest()))
    ns: dict[str, object] = {}
    heap = set()  # kernels that allocate on the heap: compiled with numba's runtime
    for mod in mods:
        ns.update({k: v for k, v in vars(mod).items() if not k.startswith("__")})
        heap.update(getattr(mod, "HEAP_KERNELS", ()))
    ns.update(scratch_intrinsics())
    compiled = {}
    for name, f in names.items():
        bound = getattr(f, "bound", None)  # a loop body of one plant (`kernels.bind`): its own namespace
        clone = types.FunctionType(f.__code__, {} if bound else ns, name, f.__defaults__, f.__closure__)
        clone.__module__ = f.__module__
        clone.__qualname__ = f.__qualname__
        compiled[name] = numba.njit(cache=True, nogil=True, _nrt=name in heap)(clone)
    ns.update(compiled)
    for name, f in names.items():
        if getattr(f, "bound", None):
            compiled[name].py_func.__globals__.update(ns, **{k: ns[v.__name__] for k, v in f.bound.items()})
    return types.SimpleNamespace(**compiled)


class _Lazy:
    """`K.name`: the kernel of `kernels()`, kept as an attribute after its first access (a plain lookup)."""

    def __getattr__(self, item):
        fn = getattr(kernels(), item)
        self.__dict__[item] = fn
        return fn


K = _Lazy()
