"""Working arrays of the kernels: the temporaries a kernel needs while it runs and never hands back.

    x = scratch(2);  J = scratch((2, 6));  Hy = scratch_cz((6, 6))

Here, in plain numpy, each is `np.empty` / `np.zeros` of that shape (float64; `_c`: complex128; `_i`:
int64; `scratch_zeros` and `scratch_cz` are zero-filled).  Compiled (`harness.loop.fast` compiles the
kernels in a namespace where these names are their numba form, `harness.loop.native.scratch_intrinsics`;
this module imports numpy only), each call site is a block of the calling kernel's stack frame instead of
a heap allocation: no malloc and free, no reference count, per call; and a kernel that makes no heap
array compiles without numba's runtime.  The per-step kernels made some 70 heap arrays per control step
before (README, Speed).

Rules, so that both forms give the same numbers:
* the shape is an int or a tuple of ints known when the kernel is compiled (a literal or a module constant);
* the array never outlives the kernel that made it: not returned, not stored in anything returned (passing
  it to a callee is fine);
* a call inside a loop of the kernel gives the same memory at every iteration (the previous iteration's
  array is overwritten): make the arrays before the loop when an iteration keeps one.
"""

from __future__ import annotations

import numpy as np


def scratch(shape):
    """Uninitialized float64 working array of `shape` (np.empty)."""
    return np.empty(shape)


def scratch_zeros(shape):
    """Zero-filled float64 working array of `shape` (np.zeros)."""
    return np.zeros(shape)


def scratch_c(shape):
    """Uninitialized complex128 working array of `shape`."""
    return np.empty(shape, dtype=np.complex128)


def scratch_cz(shape):
    """Zero-filled complex128 working array of `shape`."""
    return np.zeros(shape, dtype=np.complex128)


def scratch_i(shape):
    """Uninitialized int64 working array of `shape`."""
    return np.empty(shape, dtype=np.int64)


# (function, dtype name, zero-filled): what `harness.loop.native` compiles each into
SCRATCH_FORMS = ((scratch, "float64", False), (scratch_zeros, "float64", True),
                 (scratch_c, "complex128", False), (scratch_cz, "complex128", True),
                 (scratch_i, "int64", False))
