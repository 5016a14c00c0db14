"""Native calls of the compiled kernels: MuJoCo's C functions by address (`mj_call`) and working arrays
on the kernels' stack frames (`scratch_intrinsics`); plain-Python forms for TELEOP_NO_JIT=1."""

from __future__ import annotations

import functools

import numpy as np

MJ_STEP_FN, MJ_KINEMATICS_FN = 0, 1


def _mj_addresses():
    import ctypes
    import glob
    import os

    import mujoco

    libs = sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))
    if not libs:  # pragma: no cover - other platforms
        return np.zeros(2, dtype=np.int64)
    lib = ctypes.CDLL(libs[0])
    names = ("mj_step", "mj_kinematics")
    return np.array([ctypes.cast(getattr(lib, f), ctypes.c_void_p).value for f in names], dtype=np.int64)


# [mj_step, mj_kinematics]: an argument of the kernels, never a global (it would make them uncacheable)
MJ_FUNCS = _mj_addresses()


def mj_call(fn, mptr, dptr):
    """Call the MuJoCo C function at address fn with (mjModel*, mjData*) (ctypes; compiled: a direct call)."""
    import ctypes

    if fn == 0:  # pragma: no cover
        raise RuntimeError("MuJoCo's shared library was not found (libmujoco.so*)")
    ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(int(fn))(mptr, dptr)


@functools.cache
def register_numba_extensions() -> None:
    """The compiled form of mj_call (`harness.loop.fast` calls this before compiling)."""
    from llvmlite import ir as _ir
    from numba import types as _nbt
    from numba.extending import intrinsic as _intrinsic
    from numba.extending import overload as _overload

    @_intrinsic
    def _mj_call_ptr(typingctx, fn, mptr, dptr):
        sig = _nbt.void(fn, mptr, dptr)

        def codegen(context, builder, signature, args):
            vp = _ir.IntType(8).as_pointer()
            fnty = _ir.FunctionType(_ir.VoidType(), [vp, vp])
            f = builder.inttoptr(args[0], fnty.as_pointer())
            builder.call(f, [builder.inttoptr(args[1], vp), builder.inttoptr(args[2], vp)])
            return context.get_dummy_value()

        return sig, codegen

    @_overload(mj_call)
    def _mj_call_overload(fn, mptr, dptr):
        def impl(fn, mptr, dptr):
            _mj_call_ptr(fn, mptr, dptr)

        return impl


def _literal_dims(shape):
    """The dimensions of a numba shape type of integer literals (an int or a tuple of them), else None."""
    from numba import types as _nbt

    if isinstance(shape, _nbt.IntegerLiteral):
        return (int(shape.literal_value),)
    if isinstance(shape, _nbt.BaseTuple) and len(shape) > 0 and all(
            isinstance(t, _nbt.IntegerLiteral) for t in shape):
        return tuple(int(t.literal_value) for t in shape)
    return None


@functools.cache
def scratch_intrinsics() -> dict:
    """The compiled `controllers.scratch` functions by name: an array over an `alloca` block of the calling
    kernel's entry frame (no meminfo; zero-filled for the `_zeros` / `_cz` forms); shapes are literals."""
    from numba import types as _nbt
    from numba.core import cgutils as _cgutils
    from numba.extending import intrinsic as _intrinsic

    from controllers.scratch import SCRATCH_FORMS

    def make(dtype_name, zero):
        dtype = getattr(_nbt, dtype_name)

        def stack_array(typingctx, shape):
            dims = _literal_dims(shape)
            if dims is None or min(dims) < 0:
                return None  # numba retries with the literal types of the arguments
            aryty = _nbt.Array(dtype, len(dims), "C")

            def codegen(context, builder, signature, args):
                llty = context.get_data_type(dtype)
                count = 1
                for n in dims:
                    count *= n
                ptr = _cgutils.alloca_once(builder, llty, size=max(count, 1))
                itemsize = context.get_abi_sizeof(llty)
                if zero and count > 0:
                    _cgutils.memset(builder, ptr, context.get_constant(_nbt.intp, count * itemsize), 0)
                strides, step = [], itemsize
                for n in reversed(dims):
                    strides.insert(0, step)
                    step *= n
                ary = context.make_array(aryty)(context, builder)
                intp = [context.get_constant(_nbt.intp, v) for v in dims + tuple(strides) + (itemsize,)]
                context.populate_array(ary, data=ptr, shape=intp[:len(dims)], strides=intp[len(dims):-1],
                                       itemsize=intp[-1], meminfo=None)
                return ary._getvalue()

            return aryty(shape), codegen

        stack_array.__name__ = f"stack_{dtype_name}{'_zeros' if zero else ''}"
        return _intrinsic(stack_array)

    return {fn.__name__: make(dtype_name, zero) for fn, dtype_name, zero in SCRATCH_FORMS}


def copy_geometry(geo_in, row, geo_out):
    """Row `row` of the recording geometry from MuJoCo's kinematics: geo_in = (xpos, xquat, site_xpos,
    xanchor, bodies (nb,), gids = [elbow body, shoulder joint, master tip site, slave tip site]); geo_out =
    (body_pos (n, nb, 3), body_quat (n, nb, 4) wxyz, master_pos (n, 3, 3) shoulder/elbow/tip, tip (n, 3))."""
    xpos, xquat, site_xpos, xanchor, bodies, gids = geo_in
    body_pos, body_quat, master_pos, tip = geo_out
    for b in range(bodies.shape[0]):
        src = bodies[b]
        for j in range(3):
            body_pos[row, b, j] = xpos[src, j]
        for j in range(4):
            body_quat[row, b, j] = xquat[src, j]
    for j in range(3):
        master_pos[row, 0, j] = xanchor[gids[1], j]
        master_pos[row, 1, j] = xpos[gids[0], j]
        master_pos[row, 2, j] = site_xpos[gids[2], j]
        tip[row, j] = site_xpos[gids[3], j]


KERNELS = ("copy_geometry",)
