"""Working arrays of the kernels: temporaries a kernel needs while it runs and never hands back.

Interpreted, each is `np.empty` / `np.zeros` (float64; `_c`: complex128; `_i`: int64; `_zeros`, `_cz`:
zero-filled).  Compiled (`harness.loop.native.scratch_intrinsics`), each is a block of the calling
kernel's stack frame.  So: the shape is a compile-time int or tuple of ints; the array never outlives
the kernel (not returned or stored); a call inside a loop gives the same memory at every iteration.
"""

from __future__ import annotations

import numpy as np


def scratch(shape):
    return np.empty(shape)


def scratch_zeros(shape):
    return np.zeros(shape)


def scratch_c(shape):
    return np.empty(shape, dtype=np.complex128)


def scratch_cz(shape):
    return np.zeros(shape, dtype=np.complex128)


def scratch_i(shape):
    return np.empty(shape, dtype=np.int64)


# (function, dtype name, zero-filled): what `harness.loop.native` compiles each into
SCRATCH_FORMS = ((scratch, "float64", False), (scratch_zeros, "float64", True),
                 (scratch_c, "complex128", False), (scratch_cz, "complex128", True),
                 (scratch_i, "int64", False))
