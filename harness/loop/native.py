"""Native calls from the compiled MuJoCo loop: MuJoCo's C functions by address, and the synchronisation of
the loop with its physics thread (numba-compatible; compiled by `harness.loop.fast` with the other kernels).

Each helper below is plain Python (interpreted kernels, TELEOP_NO_JIT=1) and has a compiled form registered
by `register_numba_extensions` (called by `harness.loop.fast.kernels` before compiling; importing this module
does not import numba).  `scratch_intrinsics` gives the compiled form of `controllers.scratch` (the kernels'
working arrays on their stack frames).
"""

from __future__ import annotations

import numpy as np

# =============================================================================================
# MuJoCo's C functions by address
# =============================================================================================
# The C functions `void f(const mjModel*, mjData*)` are called through a function pointer passed as
# an argument (`mjfn` = MJ_FUNCS: [mj_step, mj_kinematics, mj_step1, mj_step2, sched_yield, usleep]
# addresses of this process), not through a ctypes object, so that numba can cache the compiled loop on disk
# (a ctypes global would bake this process' addresses into the code and make it uncacheable: ~3 s of
# compilation in every process).  sched_yield (`int f(void)`) and usleep (`int f(unsigned)`) are libc's,
# 0 where they are not found.
MJ_STEP_FN, MJ_KINEMATICS_FN, MJ_STEP1_FN, MJ_STEP2_FN, YIELD_FN, SLEEP_FN = 0, 1, 2, 3, 4, 5


def _mj_addresses():
    import ctypes
    import glob
    import os

    import mujoco

    libs = sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))
    if not libs:  # pragma: no cover - other platforms
        return np.zeros(6, dtype=np.int64)
    lib = ctypes.CDLL(libs[0])
    names = ("mj_step", "mj_kinematics", "mj_step1", "mj_step2")
    addr = [ctypes.cast(getattr(lib, f), ctypes.c_void_p).value for f in names]
    for f in ("sched_yield", "usleep"):
        try:
            addr.append(ctypes.cast(getattr(ctypes.CDLL(None), f), ctypes.c_void_p).value)
        except (AttributeError, OSError):  # pragma: no cover - no libc: waits only spin
            addr.append(0)
    return np.array(addr, dtype=np.int64)


MJ_FUNCS = _mj_addresses()  # pass to the kernels below; never use as a global inside them


def mj_call(fn, mptr, dptr):
    """Call the MuJoCo C function at address fn with (mjModel*, mjData*) (interpreted: ctypes;
    compiled: a direct indirect call, see the numba overload below)."""
    import ctypes

    if fn == 0:  # pragma: no cover
        raise RuntimeError("MuJoCo's shared library was not found (libmujoco.so*)")
    ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(int(fn))(mptr, dptr)


def sync_load(sync, i):
    """sync[i] (int64 array shared with another thread), read with acquire ordering when compiled."""
    return sync[i]


def sync_store(sync, i, value):
    """sync[i] = value, written with release ordering when compiled (see sync_load)."""
    sync[i] = value


def cpu_relax():
    """A spin-wait hint to the processor (x86 `pause`) when compiled; nothing interpreted."""


def c_yield(fn):
    """Call `int sched_yield(void)` at address fn (0: nothing): let another thread have this core."""
    if fn != 0:
        import ctypes

        ctypes.CFUNCTYPE(ctypes.c_int)(int(fn))()


def c_sleep(fn, us):
    """Call `int usleep(unsigned)` at address fn with us microseconds (0: nothing)."""
    if fn != 0:
        import ctypes

        ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint)(int(fn))(int(us))


_registered = False


def register_numba_extensions() -> None:
    """The compiled form of mj_call (called by `harness.loop.fast.kernels` before compiling: importing
    this module does not import numba)."""
    global _registered
    if _registered:
        return
    _registered = True
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

    import platform

    from numba.core import cgutils as _cgutils

    def _item_ptr(context, builder, aryty, ary, idx):
        arr = context.make_array(aryty)(context, builder, ary)
        return _cgutils.get_item_pointer(context, builder, aryty, arr, [idx])

    @_intrinsic
    def _sync_load(typingctx, sync, i):
        sig = _nbt.int64(sync, i)

        def codegen(context, builder, signature, args):
            ptr = _item_ptr(context, builder, signature.args[0], args[0], args[1])
            return builder.load_atomic(ptr, "acquire", 8)

        return sig, codegen

    @_intrinsic
    def _sync_store(typingctx, sync, i, value):
        sig = _nbt.void(sync, i, value)

        def codegen(context, builder, signature, args):
            ptr = _item_ptr(context, builder, signature.args[0], args[0], args[1])
            val = context.cast(builder, args[2], signature.args[2], _nbt.int64)
            builder.store_atomic(val, ptr, "release", 8)
            return context.get_dummy_value()

        return sig, codegen

    pause = platform.machine().lower() in ("x86_64", "amd64", "i686", "x86")

    @_intrinsic
    def _cpu_relax(typingctx):
        sig = _nbt.void()

        def codegen(context, builder, signature, args):
            if pause:  # the intrinsic, not inline assembly (numba's code emitter has no asm parser)
                fnty = _ir.FunctionType(_ir.VoidType(), [])
                builder.call(_cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse2.pause"), [])
            return context.get_dummy_value()

        return sig, codegen

    @_intrinsic
    def _c_call0(typingctx, fn):
        sig = _nbt.void(fn)

        def codegen(context, builder, signature, args):
            fnty = _ir.FunctionType(_ir.IntType(32), [])
            builder.call(builder.inttoptr(args[0], fnty.as_pointer()), [])
            return context.get_dummy_value()

        return sig, codegen

    @_intrinsic
    def _c_call1(typingctx, fn, arg):
        sig = _nbt.void(fn, arg)

        def codegen(context, builder, signature, args):
            i32 = _ir.IntType(32)
            fnty = _ir.FunctionType(i32, [i32])
            builder.call(builder.inttoptr(args[0], fnty.as_pointer()), [builder.trunc(args[1], i32)])
            return context.get_dummy_value()

        return sig, codegen

    @_overload(sync_load)
    def _sync_load_overload(sync, i):
        return lambda sync, i: _sync_load(sync, i)

    @_overload(sync_store)
    def _sync_store_overload(sync, i, value):
        return lambda sync, i, value: _sync_store(sync, i, value)

    @_overload(cpu_relax)
    def _cpu_relax_overload():
        return lambda: _cpu_relax()

    @_overload(c_yield)
    def _c_yield_overload(fn):
        def impl(fn):
            if fn != 0:
                _c_call0(fn)

        return impl

    @_overload(c_sleep)
    def _c_sleep_overload(fn, us):
        def impl(fn, us):
            if fn != 0:
                _c_call1(fn, us)

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


def scratch_intrinsics() -> dict:
    """The compiled form of `controllers.scratch`, by name, for the namespace `harness.loop.fast` compiles the
    kernels in (where each replaces the numpy function of that name): an array over a block of the calling
    kernel's stack frame (an `alloca` in its entry block, emitted into the kernel itself, so a call in a
    loop reuses one block), with no meminfo (nothing to count or free), zero-filled at each call for the
    `_zeros` / `_cz` forms.  A shape that is not made of literals is a typing error (compile time), never a
    heap array in disguise."""
    global _SCRATCH
    if _SCRATCH is not None:
        return _SCRATCH
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

    _SCRATCH = {fn.__name__: make(dtype_name, zero) for fn, dtype_name, zero in SCRATCH_FORMS}
    return _SCRATCH


_SCRATCH: dict | None = None


# =============================================================================================
# The physics thread
# =============================================================================================
# The physics thread of `mujoco_chunk` (its sync): int64 [go, state, step1, last]
#   go    (written by the loop): physics steps the loop asks for (mj_step2 of the current state, then of
#         the next, ...);
#   state (physics thread): physics steps done; qpos, qvel, sensordata hold that state;
#   step1 (physics thread): the state whose mj_step1 is done (kinematics, ... in MjData);
#   last  (set before the thread starts): no mj_step1 after the state of this many steps (the run's end).
SYNC_GO, SYNC_S2, SYNC_S1, SYNC_LAST, SYNC_SIZE = 0, 1, 2, 3, 4
SYNC_STOP = -1  # sync[SYNC_GO] = SYNC_STOP ends physics_server
# A wait for the other thread spins on x86 `pause` (~10-40 ns each; a wait within a step, a few us to a few
# hundred, ends here) with a sched_yield every SPIN iterations (a descheduled partner gets the core).  After
# NAP_AFTER iterations (some ms: no step waits that long) it naps NAP_US per iteration instead: a long wait
# (the loop's thread in Python between compiled calls, a slow live-view callback) does not keep a core busy,
# and costs the wait that ends it at most a nap.
SPIN = 2000
NAP_AFTER = 50 * SPIN
NAP_US = 200


def backoff(spins, mjfn):
    """Iteration `spins` (0, 1, ...) of a wait: pause, sched_yield or a nap (above; the libc addresses in
    mjfn = MJ_FUNCS).  Returns spins + 1."""
    if spins >= NAP_AFTER and mjfn[SLEEP_FN] != 0:
        c_sleep(mjfn[SLEEP_FN], NAP_US)
    elif spins % SPIN == SPIN - 1:
        c_yield(mjfn[YIELD_FN])
    else:
        cpu_relax()
    return spins + 1


def sync_wait(sync, slot, value, mjfn):
    """Wait until sync[slot] == value (acquire)."""
    spins = 0
    while sync_load(sync, slot) != value:
        spins = backoff(spins, mjfn)


def step1_published(mptr, dptr, mjfn, sync, g, substeps, geo_in, geo_out):
    """The physics thread's mj_step1 of the state of physics step g, the recording-geometry row of that
    state's control step (when g starts one and geo_out has rows), then sync[SYNC_S1] = g."""
    mj_call(mjfn[MJ_STEP1_FN], mptr, dptr)
    if geo_out[0].shape[0] > 0 and g % substeps == 0:
        copy_geometry(geo_in, g // substeps, geo_out)
    sync_store(sync, SYNC_S1, g)


def physics_server(mptr, dptr, mjfn, sync, wnum, wsnap, sens, sens_snap, substeps, geo_in, geo_out):
    """Physics thread of `mujoco_chunk` with a sync array (layout above): mj_step1 of the current state,
    then, each time the loop asks for the next step (sync[SYNC_GO] = state + 1), mj_step2, publish the new
    state, and mj_step1 of it (not past sync[SYNC_LAST]).  With the new state it publishes copies the loop
    reads instead of MuJoCo's own arrays:
    * sens_snap, of sensordata (sens): mj_step1 rewrites the position and velocity sensors (e.g. a contact
      distance) while the loop reads the state;
    * wsnap, of MuJoCo's warning counters (wnum, a view of mjData.warning.number): an mj_step1 of a state
      the loop then does not step (it stopped) may warn, as mj_step would not have.
    The recording geometry of control step k (`copy_geometry`, geo_in, geo_out: the whole run's rows) is
    copied here from the kinematics of mj_step1 of the state of physics step k * substeps, so that MuJoCo's
    data stays in this thread's core.  Returns when sync[SYNC_GO] == SYNC_STOP (at once if it is already):
    the number of mj_step2 calls."""
    g = sync_load(sync, SYNC_S2)
    last = sync_load(sync, SYNC_LAST)
    calls = 0
    if sync_load(sync, SYNC_GO) == SYNC_STOP:
        return calls
    if g < last:
        step1_published(mptr, dptr, mjfn, sync, g, substeps, geo_in, geo_out)
    while True:
        spins = 0
        go = sync_load(sync, SYNC_GO)
        while go == g:
            spins = backoff(spins, mjfn)
            go = sync_load(sync, SYNC_GO)
        if go == SYNC_STOP:
            break
        mj_call(mjfn[MJ_STEP2_FN], mptr, dptr)
        calls += 1
        g += 1
        for i in range(sens.shape[0]):
            sens_snap[i] = sens[i]
        for i in range(wnum.shape[0]):
            wsnap[i] = wnum[i]
        sync_store(sync, SYNC_S2, g)
        if g < last:
            step1_published(mptr, dptr, mjfn, sync, g, substeps, geo_in, geo_out)
    return calls


def copy_geometry(geo_in, row, geo_out):
    """Row `row` of the recording geometry from MuJoCo's current kinematics: geo_in = (xpos, xquat,
    site_xpos, xanchor (views of the MjData), bodies (nb,) chain body ids, gids = [elbow body, shoulder
    joint, master tip site, slave tip site]); geo_out = (body_pos (n, nb, 3), body_quat (n, nb, 4) wxyz,
    master_pos (n, 3, 3) = shoulder anchor, elbow, master tip; tip (n, 3) slave tip site)."""
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


KERNELS = ("backoff", "sync_wait", "step1_published", "physics_server", "copy_geometry")
