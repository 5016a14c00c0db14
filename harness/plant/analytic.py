"""The analytic plant: the paper's models (1) with the plant's own parameters; `plant_accel` is its forward
dynamics kernel (numba-compatible), integrated by `harness.loop.kernels.analytic_advance`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.master import master_kernel
from controllers.params import MasterParams, SlaveParams
from controllers.scratch import scratch
from controllers.slave import mass_nle_kernel
from controllers.tip import tip_kinematics


def cholesky_solve(A, b, out, L, y):
    """Solve A x = b (A (n, n) SPD) by Cholesky into out (n,); False if not SPD.  Work: L (n, n), y (n,)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]
    return True


def plant_accel(mpk, spk, nodes, weights, s, T1, T2, F, acc):
    """Analytic plant forward dynamics: acc (16,) = d/dt [q1, dq1, q2, dq2].  False if not SPD."""
    x, J1, Jd1, M1, N1 = scratch(2), scratch((2, 2)), scratch((2, 2)), scratch((2, 2)), scratch(2)
    master_kernel(mpk, s[0:2], s[2:4], x, J1, Jd1, M1, N1)
    rhs1, dd1 = scratch(2), scratch(2)
    for i in range(2):
        rhs1[i] = T1[i] - N1[i] + J1[0, i] * F[0] + J1[1, i] * F[1]
    ok1 = cholesky_solve(M1, rhs1, dd1, scratch((2, 2)), scratch(2))
    M2, N2, rhs2, dd2 = scratch((6, 6)), scratch(6), scratch(6), scratch(6)
    mass_nle_kernel(spk, s[4:10], s[10:16], nodes, weights, M2, N2)
    if F[2] != 0.0 or F[3] != 0.0:
        x2, J2, H = scratch(2), scratch((2, 6)), scratch((2, 6, 6))
        tip_kinematics(s[4:10], s[10:16], 1, x2, J2, H, H)
        for a in range(6):
            rhs2[a] = T2[a] - N2[a] + J2[0, a] * F[2] + J2[1, a] * F[3]
    else:
        for a in range(6):
            rhs2[a] = T2[a] - N2[a]
    ok2 = cholesky_solve(M2, rhs2, dd2, scratch((6, 6)), scratch(6))
    for i in range(2):
        acc[i] = s[2 + i]
        acc[2 + i] = dd1[i]
    for a in range(6):
        acc[4 + a] = s[10 + a]
        acc[10 + a] = dd2[a]
    return ok1 and ok2


KERNELS = ("cholesky_solve", "plant_accel")


@dataclass(frozen=True)
class AnalyticPlant:
    """The analytic plant's parameters (the plant's own, which may differ from the controller's)."""

    master: MasterParams
    slave: SlaveParams

    kind = "analytic"
