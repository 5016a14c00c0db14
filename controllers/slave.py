"""Analytic model of the planar 3-section Octarm slave: kinematics and Lagrangian dynamics.

q2 = [d1, d2, d3, k1, k2, k3] (section arc lengths in m, curvatures in 1/m).  Base at the origin,
tangent +Z, k > 0 bends toward +X.  Task space x2 = [X, Z] (m) of the tip.

Dynamics (paper eq. (1) with i = 2): M2(q) ddq + N2(q, dq) = T2 + J2^T F2, from the Lagrangian

    T = sum_s int_0^1 [ m_s/2 |dp_s(u)/dt|^2 + I_s/2 (dtheta_s(u)/dt)^2 ] du        (kinetic)
    V = -sum_s m_s int_0^1 g . p_s(u) du + sum_s [ Kb_s d_s k_s^2 / 2 + Ke_s (d_s - L0_s)^2 / 2 ]

with each section's mass m_s spread uniformly over its material coordinate u (so over its current
length), p_s(u) the backbone point, theta_s(u) the backbone angle and I_s an optional slice
rotational inertia.  The integrals use Gauss-Legendre quadrature with `n_quad` points per section;
the integrands are entire functions of u so 8 points are exact to rounding for |k d| <= pi/2.
N2 = C(q, dq) dq + G(q) + K(q) + D dq.  One implementation in production: `mass_nle_kernel` (M2 and N2
together, Coriolis in Lagrange form); the Christoffel form lives in tests/reference_models.py and checks it.

Public functions take the frozen `SlaveParams` and return new arrays; the `*_kernel` functions take
the packed parameter vector (`SlaveParams.packed()`, layout `controllers.params.SLAVE_PACK`) and output
arrays and are compiled by `harness.loop.fast`.
"""

from __future__ import annotations

import numpy as np

from .cc import backbone_points, term_bases, term_grad_add, term_ydd, y_of_q
from .moments import gauss_legendre01, section_moments
from .params import SLAVE_PACK, SlaveParams
from .scratch import scratch, scratch_c, scratch_cz
from .tip import tip_kinematics

PACK_L0 = SLAVE_PACK["L0"]
PACK_M = SLAVE_PACK["m"]
PACK_KB = SLAVE_PACK["Kb"]
PACK_KE = SLAVE_PACK["Ke"]
PACK_CD = SLAVE_PACK["cd"]
PACK_CK = SLAVE_PACK["ck"]
PACK_IS = SLAVE_PACK["Is"]
PACK_G = SLAVE_PACK["g"]


# ---------------------------------------------------------------------------------------------
# kernels (numba-compatible)
# ---------------------------------------------------------------------------------------------
def elastic_kernel(pk, q, out):
    """dV_elastic/dq (6,): V = sum Kb d k^2 / 2 + Ke (d - L0)^2 / 2."""
    for i in range(3):
        d = q[i]
        k = q[3 + i]
        out[i] = 0.5 * pk[PACK_KB + i] * k * k + pk[PACK_KE + i] * (d - pk[PACK_L0 + i])
        out[3 + i] = pk[PACK_KB + i] * d * k


def mass_nle_kernel(pk, q, dq, nodes, weights, M, N):
    """Fused M2 (6,6) and N2 (6,) for the control loop (outputs overwritten).

    pk: SlaveParams.packed(); q, dq (6,); nodes, weights: Gauss-Legendre rule on [0, 1]; M (6,6), N (6,) out.
    * the Coriolis/centripetal vector uses the Lagrange form for a continuum of particles,
      C(q, dq) dq = sum_s int m_s J_p^T (d^2 p/dt^2 at ddq = 0) du  (+ the slice-rotation analogue),
      with d^2 p/dt^2|_{ddq=0} = ydot^T H_y ydot + sum_i dp/dTheta_i * 2 dk_i dd_i.  It equals the
      Christoffel form C dq (tests/reference_models.py) identically (tested to rounding), without
      building the 6x6x6 tensor dM/dq;
    * along section s the point's q-gradient is affine in two scalar functions of u,
      J_p(u) = V0 + b0(u) V1 + b1(u) V2 (b_n = exp(i phi_s) u^(1+n) E_n(u Theta_s), controllers.cc
      `term_bases`; V0 = the completed sections' end terms, V1, V2 constant), and d^2 p/dt^2 is
      affine in b0, b1, b2 (`term_ydd`).  So the quadrature only accumulates the weighted moments
      sum_g w_g conj(phi_k) psi_m of (1, b0, b1, b2) (the same Gauss-Legendre points and weights),
      and M and N are assembled once per section from them: the same sums, regrouped;
    * for |Theta_s| <= 1.5 those moments come from their power series in Theta_s with coefficients
      tabulated per rule (`controllers.moments.section_moments`): the same sums again, without a
      loop over the nodes (the node loop's en_tuple and complex products were half of this kernel).
    """
    d = scratch(3)
    th = scratch(3)
    ydot = scratch(6)
    y_of_q(q, d, th, ydot, dq)
    # prefix sums over the completed sections: y-gradient and ydot^T H_y ydot of their end terms
    PJ = scratch_cz((3, 6))
    Pcor = scratch_cz(3)
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
    for a in range(6):
        N[a] = 0.0
        for b in range(6):
            M[a, b] = 0.0
    gcc = complex(pk[PACK_G + 1], -pk[PACK_G])  # conj(gravity as Z + iX)
    cen = scratch(3)  # 2 dk_i dd_i
    for i in range(3):
        cen[i] = 2.0 * dq[3 + i] * dq[i]
    Y = scratch_c((3, 6))  # y-space V0, V1, V2
    V = scratch_c((3, 6))  # q-space (B^T Y)
    Z = scratch_c((3, 6))
    Q = scratch_c((3, 4))  # Q[k, m] = sum_g w conj(phi_k) psi_m
    A = scratch_c(4)  # d^2p/dt^2 = sum_m A_m psi_m, psi = (1, b0, b1, b2)
    alpha = scratch(6)
    for s in range(3):
        ms = pk[PACK_M + s]
        Is = pk[PACK_IS + s]
        ds = d[s]
        ids = complex(0.0, ds)
        # J_p(u) = V0 + b0 V1 + b1 V2 in y-space (term_grad_add: i b0 d_s on earlier angles, b0 on
        # d_s, i b1 d_s on Theta_s)
        for a in range(6):
            Y[0, a] = PJ[s, a]
            Y[1, a] = 0.0
            Y[2, a] = 0.0
        for ll in range(s):
            Y[1, 3 + ll] = ids
        Y[1, s] = 1.0
        Y[2, 3 + s] = ids
        for k in range(3):
            for i in range(3):
                V[k, i] = Y[k, i] + Y[k, 3 + i] * q[3 + i]
                V[k, 3 + i] = Y[k, 3 + i] * q[i]
        # d^2 p/dt^2 (ddq = 0) = Pcor + term_ydd + sum_i J_p[Theta_i] cen_i, affine in (b0, b1, b2)
        P = 0.0
        for ll in range(s):
            P += ydot[3 + ll]
        D = ydot[s]
        W = ydot[3 + s]
        A[0] = Pcor[s]
        A[1] = complex(-(P * P * ds), 2.0 * P * D)
        A[2] = complex(-(2.0 * P * W * ds), 2.0 * D * W)
        A[3] = -(W * W * ds)
        for i in range(3):
            A[0] += Y[0, 3 + i] * cen[i]
            A[1] += Y[1, 3 + i] * cen[i]
            A[2] += Y[2, 3 + i] * cen[i]
        # weighted moments over the Gauss-Legendre points of the section: by their power series in
        # Theta_s (controllers.moments, the same sums) where it applies, else node by node
        if not section_moments(th[s], fs[s], nodes, Q):
            for k in range(3):
                for m in range(4):
                    Q[k, m] = 0.0
            for g in range(nodes.shape[0]):
                w = weights[g]
                b0, b1, b2, b3 = term_bases(nodes[g], th[s], fs[s])
                wb0 = w * b0.conjugate()
                wb1 = w * b1.conjugate()
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
                for a in range(6):
                    alpha[a] = 0.0
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


# ---------------------------------------------------------------------------------------------
# public API: f(params, q, dq, ...) -> array
# ---------------------------------------------------------------------------------------------
def _q(q) -> np.ndarray:
    q = np.ascontiguousarray(q, dtype=np.float64)
    if q.shape != (6,):
        raise ValueError(f"q2 must have shape (6,) [d1,d2,d3,k1,k2,k3], got {q.shape}")
    return q


def tip_position(p: SlaveParams, q) -> np.ndarray:
    """Tip x2 = [X, Z] (2,), m."""
    x = np.empty(2)
    tip_kinematics(_q(q), np.zeros(6), 0, x, np.empty((2, 6)), np.empty((2, 6, 6)), np.empty((2, 6, 6)))
    return x


def jacobian(p: SlaveParams, q) -> np.ndarray:
    """J2 = dx2/dq2 (2, 6)."""
    J = np.empty((2, 6))
    tip_kinematics(_q(q), np.zeros(6), 1, np.empty(2), J, np.empty((2, 6, 6)), np.empty((2, 6, 6)))
    return J


def tip_hessian(p: SlaveParams, q) -> np.ndarray:
    """d^2 x2 / dq2^2, (2, 6, 6)."""
    H = np.empty((2, 6, 6))
    tip_kinematics(_q(q), np.zeros(6), 2, np.empty(2), np.empty((2, 6)), H, np.empty((2, 6, 6)))
    return H


def jacobian_dot(p: SlaveParams, q, dq) -> np.ndarray:
    """dJ2/dt (2, 6) along dq."""
    return np.einsum("iab,b->ia", tip_hessian(p, q), np.asarray(dq, dtype=float))


def tip_derivatives(p: SlaveParams, q, dq) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x2 (2,), J2 (2,6), H = d^2x2/dq^2 (2,6,6), dH/dt (2,6,6))."""
    x, J, H, Hd = np.empty(2), np.empty((2, 6)), np.empty((2, 6, 6)), np.empty((2, 6, 6))
    tip_kinematics(_q(q), _q(dq), 3, x, J, H, Hd)
    return x, J, H, Hd


def backbone(p: SlaveParams, q, n_per_section: int = 20) -> np.ndarray:
    """Backbone points [X, Z] (3 n + 1, 2), m, base first, for drawing."""
    out = np.empty((3 * n_per_section + 1, 2))
    backbone_points(_q(q), int(n_per_section), out)
    return out


def mass_and_nle(p: SlaveParams, q, dq) -> tuple[np.ndarray, np.ndarray]:
    """(M2 (6,6), N2 (6,)) of paper eq. (1): `mass_nle_kernel`, the kernel of the control law and the
    plants."""
    nodes, weights = gauss_legendre01(p.n_quad)
    M, N = np.empty((6, 6)), np.empty(6)
    mass_nle_kernel(p.packed(), _q(q), _q(dq), nodes, weights, M, N)
    return M, N


def mass_matrix(p: SlaveParams, q) -> np.ndarray:
    """M2(q2) (6, 6), symmetric positive definite (units mix kg, kg m, kg m^2)."""
    return mass_and_nle(p, q, np.zeros(6))[0]


def nle(p: SlaveParams, q, dq) -> np.ndarray:
    """N2(q2, dq2) (6,) = C dq + G + elastic + damping (paper eq. (1))."""
    return mass_and_nle(p, q, dq)[1]


def gravity_force(p: SlaveParams, q) -> np.ndarray:
    """dV_gravity/dq2 (6,): the gravity part of N2 (N2 at rest with the stiffnesses set to 0)."""
    pk = p.packed()
    pk[PACK_KB:PACK_KB + 3] = 0.0
    pk[PACK_KE:PACK_KE + 3] = 0.0
    nodes, weights = gauss_legendre01(p.n_quad)
    M, N = np.empty((6, 6)), np.empty(6)
    mass_nle_kernel(pk, _q(q), np.zeros(6), nodes, weights, M, N)
    return N


def elastic_force(p: SlaveParams, q) -> np.ndarray:
    """dV_elastic/dq2 (6,): [Kb k^2/2 + Ke (d - L0), Kb d k]."""
    out = np.empty(6)
    elastic_kernel(p.packed(), _q(q), out)
    return out
