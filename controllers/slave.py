"""Analytic model of the planar 3-section Octarm, q2 = [d1, d2, d3 (m), k1, k2, k3 (1/m)], tip x2 =
[X, Z] (m): paper eq. (1), i = 2, M2 ddq + N2 = T2 + J2^T F2, N2 = C dq + G + K + D dq, from
T = sum_s int_0^1 [m_s/2 |dp_s/dt|^2 + I_s/2 (dtheta_s/dt)^2] du, V = gravity + sum_s [Kb_s d_s k_s^2 / 2
+ Ke_s (d_s - L0_s)^2 / 2] (Gauss-Legendre, `n_quad` points per section; docs/models.md).
"""

from __future__ import annotations

import numpy as np

from .cc import backbone_points, term_bases, term_grad_add, term_ydd, y_of_q
from .moments import gauss_legendre01, section_moments
from .params import SLAVE_PACK, SlaveParams
from .scratch import scratch, scratch_c, scratch_cz
from .tip import tip_kinematics

# offsets of the fields in SlaveParams.packed() (module-level ints: constants for numba)
PACK_L0, PACK_M, PACK_KB, PACK_KE, PACK_CD, PACK_CK, PACK_IS, PACK_G = (
    SLAVE_PACK[k] for k in ("L0", "m", "Kb", "Ke", "cd", "ck", "Is", "g"))


def elastic_kernel(pk, q, out):
    """dV_elastic/dq (6,): V = sum Kb d k^2 / 2 + Ke (d - L0)^2 / 2."""
    for i in range(3):
        d, k = q[i], q[3 + i]
        out[i] = 0.5 * pk[PACK_KB + i] * k * k + pk[PACK_KE + i] * (d - pk[PACK_L0 + i])
        out[3 + i] = pk[PACK_KB + i] * d * k


def mass_nle_kernel(pk, q, dq, nodes, weights, M, N):
    """M2 (6,6) and N2 (6,) (overwritten); nodes, weights: Gauss-Legendre rule on [0, 1].  C dq = sum_s int
    m_s J_p^T (d^2p/dt^2 at ddq = 0) du (+ slice rotation), J_p = V0 + b0 V1 + b1 V2 and d^2p/dt^2 affine
    in (1, b0, b1, b2), so the quadrature needs only the moments Q (`moments`)."""
    d, th, ydot = scratch(3), scratch(3), scratch(6)
    y_of_q(q, d, th, ydot, dq)
    # prefix sums over the completed sections: y-gradient and ydot^T H_y ydot of their end terms
    PJ, Pcor = scratch_cz((3, 6)), scratch_cz(3)
    fs = scratch_c(3)  # exp(i phi) at the start of each section
    fs[0] = 1.0
    phi = 0.0
    for s in range(1, 3):
        j = s - 1
        b0, b1, b2, b3 = term_bases(1.0, th[j], fs[j])
        phi += th[j]
        fs[s] = complex(np.cos(phi), np.sin(phi))
        for a in range(6):
            PJ[s, a] = PJ[j, a]
        term_grad_add(j, d[j], b0, b1, PJ[s])
        Pcor[s] = Pcor[j] + term_ydd(j, d[j], ydot, b0, b1, b2)
    M[:] = 0.0
    N[:] = 0.0
    gcc = complex(pk[PACK_G + 1], -pk[PACK_G])  # conj(gravity as Z + iX)
    cen = scratch(3)  # 2 dk_i dd_i
    for i in range(3):
        cen[i] = 2.0 * dq[3 + i] * dq[i]
    Y, V, Z = scratch_c((3, 6)), scratch_c((3, 6)), scratch_c((3, 6))  # V0, V1, V2 in y-space; V = B^T Y
    Q = scratch_c((3, 4))  # Q[k, m] = sum_g w conj(phi_k) psi_m
    A = scratch_c(4)  # d^2p/dt^2 = sum_m A_m psi_m, psi = (1, b0, b1, b2)
    alpha = scratch(6)
    for s in range(3):
        ms, Is = pk[PACK_M + s], pk[PACK_IS + s]
        ds, ids = d[s], complex(0.0, d[s])
        # J_p(u) = V0 + b0 V1 + b1 V2 in y-space (as term_grad_add)
        for a in range(6):
            Y[0, a] = PJ[s, a]
            Y[1, a] = Y[2, a] = 0.0
        for ll in range(s):
            Y[1, 3 + ll] = ids
        Y[1, s], Y[2, 3 + s] = 1.0, ids
        for k in range(3):
            for i in range(3):
                V[k, i] = Y[k, i] + Y[k, 3 + i] * q[3 + i]
                V[k, 3 + i] = Y[k, 3 + i] * q[i]
        # d^2 p/dt^2 (ddq = 0) = Pcor + term_ydd + sum_i J_p[Theta_i] cen_i, affine in (b0, b1, b2)
        P = 0.0
        for ll in range(s):
            P += ydot[3 + ll]
        D, W = ydot[s], ydot[3 + s]
        A[0] = Pcor[s]
        A[1] = complex(-(P * P * ds), 2.0 * P * D)
        A[2] = complex(-(2.0 * P * W * ds), 2.0 * D * W)
        A[3] = -(W * W * ds)
        for i in range(3):
            A[0] += Y[0, 3 + i] * cen[i]
            A[1] += Y[1, 3 + i] * cen[i]
            A[2] += Y[2, 3 + i] * cen[i]
        # the section's weighted moments: by their series (controllers.moments), else node by node
        if not section_moments(th[s], fs[s], nodes, Q):
            Q[:] = 0.0
            for g in range(nodes.shape[0]):
                w = weights[g]
                b0, b1, b2, b3 = term_bases(nodes[g], th[s], fs[s])
                wb0, wb1 = w * b0.conjugate(), w * b1.conjugate()
                Q[0, 0] += w
                Q[0, 1] += w * b0
                Q[0, 2] += w * b1
                Q[0, 3] += w * b2
                Q[1, 1] += wb0 * b0
                Q[1, 2] += wb0 * b1
                Q[1, 3] += wb0 * b2
                Q[2, 2] += wb1 * b1
                Q[2, 3] += wb1 * b2
        if Is != 0.0:  # slice rotation: sum_g Is w_g alpha alpha^T, alpha = d theta/dq at u_g
            for g in range(nodes.shape[0]):
                u = nodes[g]
                thdd = 0.0  # d^2 theta/dt^2 at ddq = 0
                alpha[:] = 0.0
                for ll in range(s + 1):
                    f = 1.0 if ll < s else u
                    alpha[ll] = f * q[3 + ll]
                    alpha[3 + ll] = f * q[ll]
                    thdd += f * 2.0 * dq[3 + ll] * dq[ll]
                iw = Is * weights[g]
                for a in range(6):
                    N[a] += iw * alpha[a] * thdd
                    for b in range(6):
                        M[a, b] += iw * alpha[a] * alpha[b]
        Q[1, 0] = Q[0, 1].conjugate()
        Q[2, 0] = Q[0, 2].conjugate()
        Q[2, 1] = Q[1, 2].conjugate()
        # M_ab += m_s Re sum_kl Q_kl conj(V_ka) V_lb;  N_a += m_s Re sum_k conj(V_ka) (sum_m Q_km A_m)
        #                                                  - m_s Re(conj(g) sum_k V_ka Q_0k)
        for a in range(6):
            for ll in range(3):
                z = 0.0j
                for k in range(3):
                    z += Q[k, ll] * V[k, a].conjugate()
                Z[ll, a] = z
        for a in range(6):
            for b in range(a, 6):
                v = 0.0
                for ll in range(3):
                    v += (Z[ll, a] * V[ll, b]).real
                v *= ms
                M[a, b] += v
                if b != a:
                    M[b, a] += v
        for k in range(3):
            uk = 0.0j
            for m in range(4):
                uk += Q[k, m] * A[m]
            gk = gcc * Q[0, k]
            for a in range(6):
                N[a] += ms * ((V[k, a].conjugate() * uk).real - (gk * V[k, a]).real)
    E = scratch(6)
    elastic_kernel(pk, q, E)
    for i in range(3):
        N[i] += E[i] + pk[PACK_CD + i] * dq[i]
        N[3 + i] += E[3 + i] + pk[PACK_CK + i] * dq[3 + i]


KERNELS = ("elastic_kernel", "mass_nle_kernel")


def _q(q) -> np.ndarray:
    q = np.ascontiguousarray(q, dtype=np.float64)
    if q.shape != (6,):
        raise ValueError(f"q2 must have shape (6,) [d1,d2,d3,k1,k2,k3], got {q.shape}")
    return q


def _tip(q, dq, order: int):
    out = np.empty(2), np.empty((2, 6)), np.empty((2, 6, 6)), np.empty((2, 6, 6))
    tip_kinematics(_q(q), _q(dq), order, *out)
    return out


def tip_position(p: SlaveParams, q) -> np.ndarray:
    """Tip x2 = [X, Z] (2,), m."""
    return _tip(q, np.zeros(6), 0)[0]


def jacobian(p: SlaveParams, q) -> np.ndarray:
    """J2 = dx2/dq2 (2, 6)."""
    return _tip(q, np.zeros(6), 1)[1]


def tip_hessian(p: SlaveParams, q) -> np.ndarray:
    """d^2 x2 / dq2^2, (2, 6, 6)."""
    return _tip(q, np.zeros(6), 2)[2]


def jacobian_dot(p: SlaveParams, q, dq) -> np.ndarray:
    """dJ2/dt (2, 6) along dq."""
    return np.einsum("iab,b->ia", tip_hessian(p, q), np.asarray(dq, dtype=float))


def tip_derivatives(p: SlaveParams, q, dq) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x2 (2,), J2 (2,6), H = d^2x2/dq^2 (2,6,6), dH/dt (2,6,6))."""
    return _tip(q, dq, 3)


def backbone(p: SlaveParams, q, n_per_section: int = 20) -> np.ndarray:
    """Backbone points [X, Z] (3 n + 1, 2), m, base first."""
    out = np.empty((3 * n_per_section + 1, 2))
    backbone_points(_q(q), int(n_per_section), out)
    return out


def mass_and_nle(p: SlaveParams, q, dq, pk=None) -> tuple[np.ndarray, np.ndarray]:
    """(M2 (6,6), N2 (6,)) of paper eq. (1) (`mass_nle_kernel`); pk: packed parameters (default p's)."""
    nodes, weights = gauss_legendre01(p.n_quad)
    M, N = np.empty((6, 6)), np.empty(6)
    mass_nle_kernel(p.packed() if pk is None else pk, _q(q), _q(dq), nodes, weights, M, N)
    return M, N


def mass_matrix(p: SlaveParams, q) -> np.ndarray:
    """M2(q2) (6, 6), symmetric positive definite (units mix kg, kg m, kg m^2)."""
    return mass_and_nle(p, q, np.zeros(6))[0]


def nle(p: SlaveParams, q, dq) -> np.ndarray:
    """N2(q2, dq2) (6,) = C dq + G + elastic + damping (paper eq. (1))."""
    return mass_and_nle(p, q, dq)[1]


def gravity_force(p: SlaveParams, q) -> np.ndarray:
    """dV_gravity/dq2 (6,): N2 at rest with the stiffnesses set to 0."""
    pk = p.packed()
    pk[PACK_KB:PACK_KB + 3] = 0.0
    pk[PACK_KE:PACK_KE + 3] = 0.0
    return mass_and_nle(p, q, np.zeros(6), pk)[1]


def elastic_force(p: SlaveParams, q) -> np.ndarray:
    """dV_elastic/dq2 (6,): [Kb k^2/2 + Ke (d - L0), Kb d k]."""
    out = np.empty(6)
    elastic_kernel(p.packed(), _q(q), out)
    return out
