"""Independent reference forms of the slave model, for tests only (interpreted, not compiled).

* The generic role-by-role CC point derivatives in y = [d, Theta] (`point_y_derivs`) and the generic
  chain rule y -> q (`chain_nz`, `chain_to_q`, `chain_to_q_dot`): checks `controllers.tip.tip_kinematics`.
* The Christoffel form of the slave dynamics (`dynamics_kernel`: M2, the exact dM2/dq2 and G2 by quadrature
  of the point Jacobians; `christoffel_coriolis`; `nle_kernel`: N2 = C dq + G + K + D dq): checks the
  production moment form `controllers.slave.mass_nle_kernel` (M2, N2, paper eq. (1)).

They share with production only E_n (`controllers.cc.en_tuple`, checked against the complex series) and the
section bases (`term_bases`); the way the derivatives and the Coriolis terms are assembled is independent.
Packed parameters: `SlaveParams.packed()` (layout `controllers.params.SLAVE_PACK`).
"""

from __future__ import annotations

import numpy as np

from controllers.cc import term_bases, y_of_q
from controllers.control import pinv_terms
from controllers.params import SLAVE_PACK, SlaveParams, SubtaskSpec
from controllers.scratch import scratch, scratch_c, scratch_cz, scratch_i, scratch_zeros
from controllers.slave import elastic_kernel, gauss_legendre01
from controllers.subtasks import beta
from controllers.tip import tip_kinematics

PACK_M = SLAVE_PACK["m"]
PACK_IS = SLAVE_PACK["Is"]
PACK_G = SLAVE_PACK["g"]
PACK_CD = SLAVE_PACK["cd"]
PACK_CK = SLAVE_PACK["ck"]


# ---------------------------------------------------------------------------------------------
# generic CC point derivatives in y and the chain rule to q
# ---------------------------------------------------------------------------------------------
def ipow_mul(k, z):
    """i^k z (exact: a swap and signs)."""
    k = k & 3
    if k == 0:
        return z
    if k == 1:
        return complex(-z.imag, z.real)
    if k == 2:
        return complex(-z.real, -z.imag)
    return complex(z.imag, -z.real)




def tval(npre, nd, nt, dj, b0, b1, b2, b3):
    """The derivative of T_j(u) = f_j u d_j E_0(u Theta_j) taken npre times in earlier angles, nd times in d_j
    and nt times in Theta_j: i^(npre + nt) b_nt, times d_j if nd = 0 (0 for nd >= 2), from the bases b_n of
    term_bases."""
    if nd >= 2:
        return 0.0j
    if nt == 0:
        b = b0
    elif nt == 1:
        b = b1
    elif nt == 2:
        b = b2
    else:
        b = b3
    v = ipow_mul(npre + nt, b)
    if nd == 0:
        v = v * dj
    return v




def ty_acc(j, npre, nd, nt, ydot, dj, b0, b1, b2, b3):
    """sum_w ydot_w tval(derivative (npre, nd, nt) of T_j, once more in y_w), w in order."""
    acc = 0.0j
    if nd == 0 and ydot[j] != 0.0:
        acc += ydot[j] * tval(npre, 1, nt, dj, b0, b1, b2, b3)
    tp = tval(npre + 1, nd, nt, dj, b0, b1, b2, b3)
    for ll in range(j):
        if ydot[3 + ll] != 0.0:
            acc += ydot[3 + ll] * tp
    if ydot[3 + j] != 0.0:
        acc += ydot[3 + j] * tval(npre, nd, nt + 1, dj, b0, b1, b2, b3)
    return acc




def term_y_derivs(j, u, d, th, phi_prev, order, ydot, c, Jy, Hy, Ty):
    """Accumulate T_j(u) and its y-derivatives into c (1,), Jy (6,), Hy (6,6), Ty (6,6) (complex).

    order 0: value; 1: + gradient; 2: + Hessian; 3: + third derivative contracted with ydot (6,).
    phi_prev: angle at the start of section j (sum of earlier Theta).  Every derivative is
    tval(npre, nd, nt) (see there): the variables of T_j play three roles, earlier angles
    y[3 + l], l < j (npre), d_j (nd) and Theta_j (nt), so each block of Hy and Ty is one value.
    """
    b0, b1, b2, b3 = term_bases(u, th[j], complex(np.cos(phi_prev), np.sin(phi_prev)))
    dj = d[j]
    c[0] += b0 * dj
    if order < 1:
        return
    # gradient: earlier angles (1,0,0), d_j (0,1,0), Theta_j (0,0,1)
    v = tval(1, 0, 0, dj, b0, b1, b2, b3)
    for ll in range(j):
        Jy[3 + ll] += v
    Jy[j] += tval(0, 1, 0, dj, b0, b1, b2, b3)
    Jy[3 + j] += tval(0, 0, 1, dj, b0, b1, b2, b3)
    if order < 2:
        return
    b = (b0, b1, b2, b3)
    add_role_blocks(j, tval(2, 0, 0, dj, *b), tval(1, 1, 0, dj, *b), tval(1, 0, 1, dj, *b),
                    tval(0, 1, 1, dj, *b), tval(0, 0, 2, dj, *b), Hy)
    if order < 3:
        return
    # Ty = sum_w ydot_w d^3 T / dy_a dy_b dy_w: one more derivative in one of the roles
    add_role_blocks(j, ty_acc(j, 2, 0, 0, ydot, dj, *b), ty_acc(j, 1, 1, 0, ydot, dj, *b),
                    ty_acc(j, 1, 0, 1, ydot, dj, *b), ty_acc(j, 0, 1, 1, ydot, dj, *b),
                    ty_acc(j, 0, 0, 2, ydot, dj, *b), Ty)




def add_role_blocks(j, v200, v110, v101, v011, v002, X):
    """Add a symmetric second-derivative pattern of T_j to X (6,6) complex: v_(npre, nd, nt) is the
    value for npre derivatives in the earlier angles y[3 + l] (l < j), nd in d_j (= y[j]) and nt in
    Theta_j (= y[3 + j]); every pair of variables gets the value of its roles."""
    dd = j
    tt = 3 + j
    for la in range(j):
        a = 3 + la
        for lb in range(j):
            X[a, 3 + lb] += v200
        X[a, dd] += v110
        X[dd, a] += v110
        X[a, tt] += v101
        X[tt, a] += v101
    X[dd, tt] += v011
    X[tt, dd] += v011
    X[tt, tt] += v002




def chain_nz(q, dq, nzu, nzb, nzbd):
    """Sparse B = dy/dq and its time derivative: column a of B has entries nzb[a, r] at rows
    nzu[a, r] (r = 0, 1); nzbd holds the matching entries of dB/dt."""
    for i in range(3):
        # column d_i: y[d_i] = d_i (1), y[Theta_i] = k_i d_i (k_i)
        nzu[i, 0] = i
        nzb[i, 0] = 1.0
        nzbd[i, 0] = 0.0
        nzu[i, 1] = 3 + i
        nzb[i, 1] = q[3 + i]
        nzbd[i, 1] = dq[3 + i]
        # column k_i: y[Theta_i] (d_i); second slot unused
        nzu[3 + i, 0] = 3 + i
        nzb[3 + i, 0] = q[i]
        nzbd[3 + i, 0] = dq[i]
        nzu[3 + i, 1] = 3 + i
        nzb[3 + i, 1] = 0.0
        nzbd[3 + i, 1] = 0.0




def chain_to_q(order, Jy, Hy, Ty, nzu, nzb, nzbd, Jq, Hq, Hqd):
    """Exact chain rule y -> q.  Jq (6,), Hq (6,6) = d^2 c/dq^2, Hqd (6,6) = d/dt Hq (complex).

    Jq = B^T Jy;  Hq = B^T Hy B + sum_i Jy[Theta_i] (E_{d_i k_i} + E_{k_i d_i});
    Hqd = dB^T Hy B + B^T Hy dB + B^T Ty B + sum_i (Hy ydot)[Theta_i] (E_{d_i k_i} + E_{k_i d_i}),
    where Ty = sum_w d^3c/dy dy dy_w ydot_w and ydot = B dq.  (Needs ydot only through Ty.)
    """
    for a in range(6):
        acc = 0.0j
        for r in range(2):
            acc += Jy[nzu[a, r]] * nzb[a, r]
        Jq[a] = acc
    if order < 2:
        return
    for a in range(6):
        for b in range(6):
            acc = 0.0j
            for r in range(2):
                ua = nzu[a, r]
                ba = nzb[a, r]
                if ba == 0.0:
                    continue
                for s in range(2):
                    acc += Hy[ua, nzu[b, s]] * ba * nzb[b, s]
            Hq[a, b] = acc
    for i in range(3):
        Hq[i, 3 + i] += Jy[3 + i]
        Hq[3 + i, i] += Jy[3 + i]




def chain_to_q_dot(Jy, Hy, Ty, ydot, nzu, nzb, nzbd, Hqd):
    """Hqd = d/dt (d^2 c / dq^2) along the motion (see chain_to_q)."""
    for a in range(6):
        for b in range(6):
            acc = 0.0j
            for r in range(2):
                ua = nzu[a, r]
                for s in range(2):
                    ub = nzu[b, s]
                    acc += Ty[ua, ub] * nzb[a, r] * nzb[b, s]
                    acc += Hy[ua, ub] * (nzbd[a, r] * nzb[b, s] + nzb[a, r] * nzbd[b, s])
            Hqd[a, b] = acc
    for i in range(3):
        jd = 0.0j
        for w in range(6):
            jd += Hy[3 + i, w] * ydot[w]
        Hqd[i, 3 + i] += jd
        Hqd[3 + i, i] += jd




def point_y_derivs(s, u, d, th, order, ydot, c, Jy, Hy, Ty):
    """Point at material coordinate u of section s: value and y-derivatives (zeroes outputs)."""
    c[0] = 0.0
    for a in range(6):
        Jy[a] = 0.0
        for b in range(6):
            Hy[a, b] = 0.0
            Ty[a, b] = 0.0
    phi = 0.0
    for j in range(s + 1):
        term_y_derivs(j, 1.0 if j < s else u, d, th, phi, order, ydot, c, Jy, Hy, Ty)
        phi += th[j]




# ---------------------------------------------------------------------------------------------
# Christoffel form of the slave dynamics
# ---------------------------------------------------------------------------------------------
def dynamics_kernel(pk, q, nodes, weights, want_dM, M, dM, G):
    """Mass matrix M (6,6), its derivative dM[a, b, c] = dM_ab/dq_c (6,6,6) if want_dM, and the
    gravity generalized force G (6,) = dV_gravity/dq (all outputs overwritten)."""
    d = scratch(3)
    th = scratch(3)
    ydot = scratch_zeros(6)
    zero6 = scratch_zeros(6)
    y_of_q(q, d, th, ydot, zero6)
    nzu = scratch_i((6, 2))
    nzb = scratch((6, 2))
    nzbd = scratch((6, 2))
    chain_nz(q, zero6, nzu, nzb, nzbd)
    c = scratch_cz(1)
    Jy = scratch_cz(6)
    Hy = scratch_cz((6, 6))
    Ty = scratch_cz((6, 6))
    Jq = scratch_c(6)
    Hq = scratch_c((6, 6))
    alpha = scratch(6)
    for a in range(6):
        G[a] = 0.0
        for b in range(6):
            M[a, b] = 0.0
            if want_dM:
                for e in range(6):
                    dM[a, b, e] = 0.0
    gc = complex(pk[PACK_G + 1], pk[PACK_G])  # gravity as Z + iX
    order = 2 if want_dM else 1
    for s in range(3):
        ms = pk[PACK_M + s]
        Is = pk[PACK_IS + s]
        for g in range(nodes.shape[0]):
            u = nodes[g]
            w = weights[g]
            point_y_derivs(s, u, d, th, order, ydot, c, Jy, Hy, Ty)
            chain_to_q(order, Jy, Hy, Ty, nzu, nzb, nzbd, Jq, Hq, Hq)
            mw = ms * w
            for a in range(6):
                G[a] -= mw * (gc.conjugate() * Jq[a]).real
                for b in range(a, 6):
                    v = mw * (Jq[a].conjugate() * Jq[b]).real
                    M[a, b] += v
                    if b != a:
                        M[b, a] += v
            if want_dM:
                for a in range(6):
                    for b in range(a, 6):
                        for e in range(6):
                            v = mw * (Hq[a, e].conjugate() * Jq[b] + Jq[a].conjugate() * Hq[b, e]).real
                            dM[a, b, e] += v
                            if b != a:
                                dM[b, a, e] += v
            if Is != 0.0:
                # backbone angle theta = sum_{l<s} Theta_l + u Theta_s;  alpha = dtheta/dq
                for a in range(6):
                    alpha[a] = 0.0
                for ll in range(s + 1):
                    f = 1.0 if ll < s else u
                    alpha[ll] = f * q[3 + ll]
                    alpha[3 + ll] = f * q[ll]
                iw = Is * w
                for a in range(6):
                    for b in range(6):
                        M[a, b] += iw * alpha[a] * alpha[b]
                if want_dM:
                    # d alpha_a / dq_e is f when {a, e} = {l, 3+l}
                    for ll in range(s + 1):
                        f = 1.0 if ll < s else u
                        for b in range(6):
                            # e = 3+l differentiates alpha[l]; e = l differentiates alpha[3+l]
                            dM[ll, b, 3 + ll] += iw * f * alpha[b]
                            dM[b, ll, 3 + ll] += iw * f * alpha[b]
                            dM[3 + ll, b, ll] += iw * f * alpha[b]
                            dM[b, 3 + ll, ll] += iw * f * alpha[b]




def christoffel_coriolis(dM, dq, C):
    """C (6,6) with C_ij = sum_k Gamma_ijk dq_k, Gamma_ijk = (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i)/2."""
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                acc += (dM[i, j, k] + dM[i, k, j] - dM[j, k, i]) * dq[k]
            C[i, j] = 0.5 * acc




def nle_kernel(pk, q, dq, nodes, weights, M, dM, C, out):
    """N2 (6,) = C dq + G + K + D dq; also fills M, dM and C (work arrays the caller may reuse)."""
    G = scratch(6)
    dynamics_kernel(pk, q, nodes, weights, True, M, dM, G)
    christoffel_coriolis(dM, dq, C)
    elastic_kernel(pk, q, out)
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += C[i, j] * dq[j]
        out[i] += acc + G[i]
    for i in range(3):
        out[i] += pk[PACK_CD + i] * dq[i]
        out[3 + i] += pk[PACK_CK + i] * dq[3 + i]




# ---------------------------------------------------------------------------------------------
# f(params, q, dq) -> array
# ---------------------------------------------------------------------------------------------
def _dyn(p: SlaveParams, q, want_dM: bool = True):
    nodes, weights = gauss_legendre01(p.n_quad)
    M, dM, G = np.empty((6, 6)), np.zeros((6, 6, 6)), np.empty(6)
    dynamics_kernel(p.packed(), np.asarray(q, dtype=float), nodes, weights, want_dM, M, dM, G)
    return M, dM, G


def mass_matrix(p: SlaveParams, q) -> np.ndarray:
    """M2 (6, 6) by quadrature of the point Jacobians."""
    return _dyn(p, q, False)[0]


def mass_matrix_derivative(p: SlaveParams, q) -> np.ndarray:
    """dM2/dq2 (6, 6, 6), [a, b, c] = d M_ab / d q_c (exact)."""
    return _dyn(p, q)[1]


def gravity_force(p: SlaveParams, q) -> np.ndarray:
    """dV_gravity/dq2 (6,)."""
    return _dyn(p, q, False)[2]


def coriolis_matrix(p: SlaveParams, q, dq) -> np.ndarray:
    """C(q2, dq2) (6, 6) from the Christoffel symbols of dM2/dq2."""
    C = np.empty((6, 6))
    christoffel_coriolis(mass_matrix_derivative(p, q), np.asarray(dq, dtype=float), C)
    return C


def nle(p: SlaveParams, q, dq) -> np.ndarray:
    """N2 (6,) = C dq + G + K + D dq, Christoffel form."""
    nodes, weights = gauss_legendre01(p.n_quad)
    out = np.empty(6)
    nle_kernel(p.packed(), np.asarray(q, dtype=float), np.asarray(dq, dtype=float), nodes, weights,
               np.empty((6, 6)), np.empty((6, 6, 6)), np.empty((6, 6)), out)
    return out


def tip_generic(q, dq):
    """Tip c (complex), Jq (6,), Hq (6, 6), Hqd (6, 6) (complex, c = Z + i X) by the generic path."""
    q = np.asarray(q, dtype=float)
    dq = np.asarray(dq, dtype=float)
    d, th, ydot = np.empty(3), np.empty(3), np.empty(6)
    y_of_q(q, d, th, ydot, dq)
    c = np.zeros(1, complex)
    Jy, Hy, Ty = np.zeros(6, complex), np.zeros((6, 6), complex), np.zeros((6, 6), complex)
    point_y_derivs(2, 1.0, d, th, 3, ydot, c, Jy, Hy, Ty)
    nzu, nzb, nzbd = np.empty((6, 2), np.int64), np.empty((6, 2)), np.empty((6, 2))
    chain_nz(q, dq, nzu, nzb, nzbd)
    Jq, Hq, Hqd = np.empty(6, complex), np.empty((6, 6), complex), np.empty((6, 6), complex)
    chain_to_q(3, Jy, Hy, Ty, nzu, nzb, nzbd, Jq, Hq, Hqd)
    chain_to_q_dot(Jy, Hy, Ty, ydot, nzu, nzb, nzbd, Hqd)
    return c[0], Jq, Hq, Hqd


# ---------------------------------------------------------------------------------------------
# null space (paper eqs. (23)-(33)) with numpy
# ---------------------------------------------------------------------------------------------
def null_space_reference(spec: SubtaskSpec, slave: SlaveParams, ky: float, ks: float, q, dq):
    """(y_a, J_s (6,), g (6,), dg/dt (6,)) of eqs. (29), (31), (33) and the exact time derivative."""
    b, grad, graddot = beta(spec, slave, q, dq)
    dq = np.asarray(dq, dtype=float)
    ya = np.exp(-ky * b)
    yad = -ky * ya * (grad @ dq)
    Js = -ky * ya * grad
    g = ks * ky * ya * ya * grad
    gd = ks * ky * (2.0 * ya * yad * grad + ya * ya * graddot)
    return ya, Js, g, gd


def null_space_quantities(p: SlaveParams, q2, dq2, g, dg):
    """(J2^+ (6,2), dJ2^+/dt (6,2), P = I - J2^+ J2 (6,6), J_phi (6,6) of (26), de_N (6,) of (23)) at
    (q2, dq2) for a given g (6,); dg is accepted for symmetry with (27) and unused.  Reference for
    tests (numpy, allocating)."""
    q2 = np.ascontiguousarray(q2, dtype=float)
    dq2 = np.ascontiguousarray(dq2, dtype=float)
    x, J, H, Hd = np.empty(2), np.empty((2, 6)), np.empty((2, 6, 6)), np.empty((2, 6, 6))
    tip_kinematics(q2, dq2, 2, x, J, H, Hd)
    Jd = np.einsum("iab,b->ia", H, dq2)
    Jp, Jpd = np.zeros((6, 2)), np.zeros((6, 2))
    pinv_terms(J, Jd, Jp, Jpd)
    P = np.eye(6) - Jp @ J
    Jphi = Jpd @ J + Jp @ Jd @ Jp @ J
    deN = P @ (np.asarray(g) - dq2)
    return Jp, Jpd, P, Jphi, deN
