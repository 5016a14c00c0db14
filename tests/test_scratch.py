"""The kernels' working arrays (`controllers.scratch`): compiled, a block of the kernel's stack frame; the
same numbers as numpy's arrays; and no heap allocation per control step in the compiled loops."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from controllers.scratch import scratch, scratch_c, scratch_cz, scratch_i, scratch_zeros

pytestmark = pytest.mark.skipif(os.environ.get("TELEOP_NO_JIT") == "1",
                                reason="interpreted kernels requested (TELEOP_NO_JIT=1): nothing is compiled")


def _fill(a, v):
    for i in range(a.shape[0]):
        a[i] = v + i


def _use_every_form(rounds):
    """Each form in a loop (the same block every round: the zero forms must be zero again), filled by a
    callee, read back here."""
    total = 0.0 + 0.0j
    dirty = 0
    for r in range(rounds):
        z = scratch_zeros((2, 3))
        cz = scratch_cz(4)
        for i in range(2):
            for j in range(3):
                if z[i, j] != 0.0:
                    dirty += 1
        for i in range(4):
            if cz[i] != 0.0:
                dirty += 1
        z[1, 2] = r + 1.0
        cz[3] = r + 1.0j
        a = scratch(5)
        _fill(a, r)
        c = scratch_c((2, 2))
        c[0, 0] = 1.0 + 2.0j
        c[1, 1] = a[4]
        k = scratch_i(3)
        k[0] = r
        k[1] = 2 * r
        k[2] = k[0] + k[1]
        total += a.sum() + c[0, 0] + c[1, 1] + z.sum() + cz.sum() + k[2]
    return total, dirty


def _compiled(fn, *helpers):
    """fn compiled the way `harness.loop.fast` compiles the kernels: the scratch names are their numba form,
    without numba's runtime (helpers are compiled alike)."""
    import types

    import numba

    from harness.loop.native import scratch_intrinsics

    ns = dict(fn.__globals__)
    ns.update(scratch_intrinsics())

    def jit(f):
        return numba.njit(_nrt=False)(types.FunctionType(f.__code__, ns, f.__name__))

    for h in helpers:
        ns[h.__name__] = jit(h)
    return jit(fn)


def test_scratch_arrays_give_numpys_numbers_and_fresh_zeros():
    """Compiled and interpreted: the same sums, and the zero forms are zero at every round, although the
    compiled form reuses one block of the stack frame."""
    fast = _compiled(_use_every_form, _fill)
    for rounds in (1, 7):
        expected = _use_every_form(rounds)
        got = fast(rounds)
        assert got[1] == 0 and expected[1] == 0
        assert got[0] == expected[0]


def test_a_shape_not_known_when_compiling_is_a_typing_error():
    """A run-time shape would need the heap: refused when the kernel compiles, never silently allocated."""
    import numba

    def bad(n):
        a = scratch(n)
        a[0] = 1.0
        return a[0]

    with pytest.raises(numba.core.errors.TypingError):
        _compiled(bad)(3)


_NO_ALLOCATION_SCRIPT = textwrap.dedent("""
    import os, sys
    os.environ["NUMBA_NRT_STATS"] = "1"
    import numpy as np
    from numba.core.runtime import rtsys
    from harness.config.scenario import Scenario
    from harness.loop.common import compile_model, noise_table
    from harness.loop.fast import kernels
    from harness.loop.trajectory import ROW_WIDTH
    from controllers import master

    K = kernels(True)
    scn = Scenario(duration=0.2)
    n = scn.n_steps
    model = compile_model(scn)
    rows = np.zeros((n, ROW_WIDTH))
    plant = (model, model.F, scn.control_dt, 1, False, master.packed(scn.plant_master),
             scn.plant_slave.packed(), np.empty((4, 16)), np.empty(16))

    def run(k0, k1, state):
        noise, scale = noise_table(scn, n)  # fresh: its running power sums are updated in place
        ring = np.zeros((1, 8))  # the actuation-delay ring (no delay)
        return K.analytic_chunk(k0, k1, model, (state, noise, scale, rows, ring, 0, scn.control_dt), plant)

    run(0, 1, model.s0.copy())  # compile or load
    counts = []
    for steps in (1, n):
        before = rtsys.get_allocation_stats()
        st, done = run(0, steps, model.s0.copy())
        after = rtsys.get_allocation_stats()
        assert st == 0 and done == steps, (st, done)
        counts.append(after.alloc - before.alloc)
    print(counts[0], counts[1])
""")


@pytest.mark.slow
def test_the_compiled_control_step_allocates_nothing_per_step():
    """The analytic loop (both laws with the null-space terms, noise, record rows, RK4 of the analytic plant:
    every per-step kernel of the MuJoCo loop but MuJoCo's step and the chain maps) makes the same number of
    heap allocations for 1 step as for a whole run: none per step (numba's own allocation counter).  It is
    compiled without numba's runtime (not in a HEAP_KERNELS list), so a heap array added to any kernel it
    calls fails here, at compile time."""
    out = subprocess.run([sys.executable, "-c", _NO_ALLOCATION_SCRIPT], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    one, many = (int(v) for v in out.stdout.split()[-2:])
    assert many == one, f"{many - one} heap allocations over {200 - 1} more steps"


_NO_ALLOCATION_MUJOCO_SCRIPT = textwrap.dedent("""
    import os
    os.environ["NUMBA_NRT_STATS"] = "1"
    os.environ["TELEOP_NO_AOT"] = "1"  # the jitted loop: numba's runtime counts its allocations
    from numba.core.runtime import rtsys
    from harness.config.scenario import Scenario
    from harness.loop.mujoco_loop import simulate_mujoco

    simulate_mujoco(Scenario(duration=0.01))  # compile or load
    counts = []
    for duration in (0.01, 0.3):
        before = rtsys.get_allocation_stats()
        tr = simulate_mujoco(Scenario(duration=duration))
        after = rtsys.get_allocation_stats()
        assert tr.status == "ok" and len(tr) == round(duration * 1000), (tr.status, len(tr))
        counts.append(after.alloc - before.alloc)
    print(counts[0], counts[1])
""")


@pytest.mark.slow
def test_the_mujoco_loop_allocates_nothing_per_step():
    """A MuJoCo run makes the same number of heap allocations in 10 steps as in 300, each one compiled
    call: nothing per step, in the loop body (`mujoco_chunk`, compiled without numba's runtime since its
    argument groups are built in Python) or in the kernels it calls."""
    out = subprocess.run([sys.executable, "-c", _NO_ALLOCATION_MUJOCO_SCRIPT], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    few, many = (int(v) for v in out.stdout.split()[-2:])
    assert many == few, f"{many - few} heap allocations over 290 more steps"
