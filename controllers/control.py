"""The paper's control laws on the analytic models (numba-compatible kernels).

Master (12)-(13):  T1 = M1 u1 + N1 - J1^T F1,  u1 = J1^-1 (ddx_d + k1 de1 + k2 e1 - dJ1 dq1).
Slave (17)-(18):   T2 = M2 u2 + N2 - J2^T F2,
                   u2 = J2^+ (ddx_d + k1 de1 + k2 e1 + k3 de2 + k4 e2 - dJ2 dq2) + phi_N,
e1 = x_d - x1 (11), e2 = x1 - x2 (16), J2^+ = J2^T (J2 J2^T)^-1 (7), de_N = P (g - dq2) (23),
J_phi = dJ2^+ J2 + J2^+ dJ2 J2^+ J2 (26), phi_N = P (dg + kn de_N) - J_phi (g - dq2) (27),
P = I - J2^+ J2, g and dg from the sub-task (33); dJ2^+ exact.  (The paper's (28) prints +kn: a sign typo.)
"""

from __future__ import annotations

import numpy as np

from .cc import gram_terms
from .master import master_kernel
from .params import Gains, SlaveParams, SubtaskSpec
from .scratch import scratch, scratch_zeros
from .slave import gauss_legendre01, mass_nle_kernel
from .status import ST_MASTER_SINGULAR, ST_OK, ST_SLAVE_SINGULAR
from .subtasks import pack_subtask, subtask_kernel
from .tip import tip_kinematics

# layout of the master info vector
MI_X1, MI_E1, MI_DE1, MI_A1, MI_DX1 = 0, 2, 4, 6, 8
MASTER_INFO = 10
# layout of the slave info vector
SI_X2, SI_E2, SI_DE2, SI_BETA, SI_YA, SI_DET, SI_BM, SI_BL = 0, 2, 4, 6, 7, 8, 9, 10
SLAVE_INFO = 11
DET_MIN = 1e-14  # det(J2 J2^T) below this is reported as a singular configuration


def master_control_kernel(pk, gains, q, dq, xd, dxd, ddxd, F1, T1, info):
    """Master law (12)-(13): writes T1 (2,) and info (MASTER_INFO,) = x1, e1, de1, a1 = ddx_d + k1 de1 +
    k2 e1, dx1.  Returns det(J1) (0: singular, T1 not written)."""
    x, J, Jd, M, N = scratch(2), scratch((2, 2)), scratch((2, 2)), scratch((2, 2)), scratch(2)
    master_kernel(pk, q, dq, x, J, Jd, M, N)
    k1, k2 = gains[0], gains[1]
    v = scratch(2)
    for i in range(2):
        dx = J[i, 0] * dq[0] + J[i, 1] * dq[1]
        e = xd[i] - x[i]
        de = dxd[i] - dx
        a = ddxd[i] + k1 * de + k2 * e
        info[MI_X1 + i] = x[i]
        info[MI_E1 + i] = e
        info[MI_DE1 + i] = de
        info[MI_A1 + i] = a
        info[MI_DX1 + i] = dx
        v[i] = a - (Jd[i, 0] * dq[0] + Jd[i, 1] * dq[1])
    det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    if det == 0.0:
        return det
    u0 = (J[1, 1] * v[0] - J[0, 1] * v[1]) / det
    u1 = (-J[1, 0] * v[0] + J[0, 0] * v[1]) / det
    for i in range(2):
        T1[i] = M[i, 0] * u0 + M[i, 1] * u1 + N[i] - (J[0, i] * F1[0] + J[1, i] * F1[1])
    return det


def pinv_terms(J, Jd, Jp, Jpd):
    """J^+ = J^T (J J^T)^-1 (6,2) and its exact time derivative (6,2).  Returns det(J J^T)."""
    g = scratch(6)
    gram_terms(J, Jd, g)
    A00, A01, A11, D00, D01, D11 = g[0], g[1], g[2], g[3], g[4], g[5]
    det = A00 * A11 - A01 * A01
    if det <= DET_MIN:
        return det
    i00, i01, i11 = A11 / det, -A01 / det, A00 / det  # A^-1
    # W = A^-1 dA A^-1 (symmetric)
    t00 = D00 * i00 + D01 * i01
    t01 = D00 * i01 + D01 * i11
    t10 = D01 * i00 + D11 * i01
    t11 = D01 * i01 + D11 * i11
    W00 = i00 * t00 + i01 * t10
    W01 = i00 * t01 + i01 * t11
    W11 = i01 * t01 + i11 * t11
    for a in range(6):
        Jp[a, 0] = J[0, a] * i00 + J[1, a] * i01
        Jp[a, 1] = J[0, a] * i01 + J[1, a] * i11
        Jpd[a, 0] = Jd[0, a] * i00 + Jd[1, a] * i01 - (J[0, a] * W00 + J[1, a] * W01)
        Jpd[a, 1] = Jd[0, a] * i01 + Jd[1, a] * i11 - (J[0, a] * W01 + J[1, a] * W11)
    return det


def slave_control_kernel(pk, nodes, weights, gains, spec, q, dq, x1, dx1, a1, F2, T2, u2, deN, info):
    """Slave law (17)-(18) with the null-space terms (23)-(33); gains [k1, k2, k3, k4, ky, ks, kn (, e2_sign,
    null_space_scale)]; q, dq (6,); x1, dx1, a1 (2,) master tip, velocity, commanded acceleration.  Writes
    T2, u2, deN (6,), info (SLAVE_INFO,).  Returns det(J2 J2^T); <= DET_MIN: singular, T2 = u2 = 0."""
    k3, k4, ky, ks, kn = gains[2], gains[3], gains[4], gains[5], gains[6]
    sgn = 1.0  # fault factors: e2 sign and null-space scale
    nss = 1.0
    if gains.shape[0] > 8:
        sgn = gains[7]
        nss = gains[8]
    x, J, H, Hd = scratch(2), scratch((2, 6)), scratch((2, 6, 6)), scratch((2, 6, 6))
    tip_kinematics(q, dq, 3, x, J, H, Hd)
    Jd = scratch_zeros((2, 6))
    for i in range(2):
        for a in range(6):
            acc = 0.0
            for b in range(6):
                acc += H[i, a, b] * dq[b]
            Jd[i, a] = acc
    Jp, Jpd = scratch_zeros((6, 2)), scratch_zeros((6, 2))
    det = pinv_terms(J, Jd, Jp, Jpd)
    # task-space errors (16)
    v = scratch(2)
    for i in range(2):
        dx2 = jdq = 0.0
        for a in range(6):
            dx2 += J[i, a] * dq[a]
            jdq += Jd[i, a] * dq[a]
        e = x1[i] - x[i]
        de = dx1[i] - dx2
        info[SI_X2 + i] = x[i]
        info[SI_E2 + i] = e
        info[SI_DE2 + i] = de
        v[i] = a1[i] + sgn * (k3 * de + k4 * e) - jdq
    info[SI_DET] = det
    if det <= DET_MIN:
        for a in range(6):
            T2[a] = u2[a] = deN[a] = 0.0
        info[SI_BETA] = info[SI_BM] = info[SI_BL] = 0.0
        info[SI_YA] = 1.0
        return det
    # sub-task (29)-(33): g = ks ky y^2 grad beta, dg exact
    grad, graddot, parts = scratch(6), scratch(6), scratch(3)
    beta = subtask_kernel(spec, J, H, Jd, Hd, q, dq, grad, graddot, parts)
    ya = np.exp(-ky * beta)
    betad = 0.0
    for a in range(6):
        betad += grad[a] * dq[a]
    yad = -ky * ya * betad
    g, gd = scratch(6), scratch(6)
    for a in range(6):
        g[a] = ks * ky * ya * ya * grad[a]
        gd[a] = ks * ky * (2.0 * ya * yad * grad[a] + ya * ya * graddot[a])
    info[SI_BETA] = parts[0]
    info[SI_YA] = ya
    info[SI_BM] = parts[0]
    info[SI_BL] = parts[1]
    # projector P = I - J^+ J, J_phi (26)
    P, JpJ = scratch((6, 6)), scratch((6, 6))
    for a in range(6):
        for b in range(6):
            s = Jp[a, 0] * J[0, b] + Jp[a, 1] * J[1, b]
            JpJ[a, b] = s
            P[a, b] = (1.0 if a == b else 0.0) - s
    # JdJpJ = dJ J^+ J (2,6)
    JdJpJ = scratch((2, 6))
    for i in range(2):
        for b in range(6):
            acc = 0.0
            for a in range(6):
                acc += Jd[i, a] * JpJ[a, b]
            JdJpJ[i, b] = acc
    r = scratch(6)  # g - dq
    for a in range(6):
        r[a] = g[a] - dq[a]
    for a in range(6):
        acc = 0.0
        for b in range(6):
            acc += P[a, b] * r[b]
        deN[a] = acc
    # J_phi r = dJ^+ (J r) + J^+ (dJ J^+ J r)
    Jr0 = Jr1 = Kr0 = Kr1 = 0.0
    for b in range(6):
        Jr0 += J[0, b] * r[b]
        Jr1 += J[1, b] * r[b]
        Kr0 += JdJpJ[0, b] * r[b]
        Kr1 += JdJpJ[1, b] * r[b]
    phi = scratch(6)
    for a in range(6):
        acc = 0.0
        for b in range(6):
            acc += P[a, b] * (gd[b] + kn * deN[b])
        phi[a] = acc - (Jpd[a, 0] * Jr0 + Jpd[a, 1] * Jr1 + Jp[a, 0] * Kr0 + Jp[a, 1] * Kr1)
    for a in range(6):
        u2[a] = Jp[a, 0] * v[0] + Jp[a, 1] * v[1] + nss * phi[a]
    # T2 = M u2 + N2 - J^T F2 (17)
    M, N = scratch((6, 6)), scratch(6)
    mass_nle_kernel(pk, q, dq, nodes, weights, M, N)
    for a in range(6):
        acc = N[a] - (J[0, a] * F2[0] + J[1, a] * F2[1])
        for b in range(6):
            acc += M[a, b] * u2[b]
        T2[a] = acc
    return det


def control_laws(mpk, spk, nodes, weights, gains, spec, sensed, xd, dxd, ddxd, F, T1, T2, u2, deN,
                 minfo, sinfo):
    """The paper's whole law on sensed (16,) = [q1, dq1, q2, dq2], x_d, dx_d, ddx_d (2,) (40) and forces
    F (4,) N: writes T1 (2,), T2, u2, deN (6,), minfo, sinfo.  Returns ST_OK, ST_MASTER_SINGULAR or
    ST_SLAVE_SINGULAR."""
    q1 = sensed[0:2]
    dq1 = sensed[2:4]
    q2 = sensed[4:10]
    dq2 = sensed[10:16]
    det1 = master_control_kernel(mpk, gains, q1, dq1, xd, dxd, ddxd, F[0:2], T1, minfo)
    if det1 == 0.0:
        return ST_MASTER_SINGULAR
    det2 = slave_control_kernel(spk, nodes, weights, gains, spec, q2, dq2, minfo[0:2], minfo[8:10],
                                minfo[6:8], F[2:4], T2, u2, deN, sinfo)
    if det2 <= DET_MIN:
        return ST_SLAVE_SINGULAR
    return ST_OK


KERNELS = ("master_control_kernel", "pinv_terms", "slave_control_kernel", "control_laws")


def slave_control(p: SlaveParams, gains: Gains, spec: SubtaskSpec, q2, dq2, x1, dx1, a1,
                  F2=(0.0, 0.0)) -> dict:
    """Slave law (17)-(18) with null-space terms: dict of T2, u2, deN (6,), x2, e2, de2 (2,), beta, ya,
    det, beta_limits.  Raises FloatingPointError when J2 J2^T is singular."""
    nodes, weights = gauss_legendre01(p.n_quad)
    T2, u2, deN, info = np.zeros(6), np.zeros(6), np.zeros(6), np.empty(SLAVE_INFO)
    f = [np.ascontiguousarray(v, dtype=float) for v in (q2, dq2, x1, dx1, a1, F2)]
    det = slave_control_kernel(p.packed(), nodes, weights, gains.packed(), pack_subtask(spec, p), *f,
                               T2, u2, deN, info)
    if det <= DET_MIN:
        raise FloatingPointError(f"slave J2 J2^T is singular (det = {det:.3e})")
    return {"T2": T2, "u2": u2, "deN": deN, "x2": info[0:2], "e2": info[2:4], "de2": info[4:6],
            "beta": info[SI_BETA], "ya": info[SI_YA], "det": det, "beta_limits": info[SI_BL]}
