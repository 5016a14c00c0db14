"""Planar constant-curvature (CC) kinematics with exact derivatives up to third order.

Representation.  A point of the plane is the complex number c = Z + i X (Z up, X right).  The
backbone tangent at arc angle phi is exp(i phi): phi = 0 is +Z, phi > 0 turns toward +X, so a
positive curvature bends toward +X.

Section j (0, 1, 2) has length d_j, curvature k_j and total bending angle Theta_j = k_j d_j.  The
point at material coordinate u in [0, 1] of section s is

    c_s(u) = sum_{j<s} T_j(1) + T_s(u),     T_j(u) = exp(i phi_{j-1}) u d_j E_0(u Theta_j),

with phi_{j-1} = sum_{l<j} Theta_l and E_n(t) = int_0^1 v^n exp(i t v) dv, an entire function
(E_0(t) = sinc(t) + i versinc(t), E_0(0) = 1), evaluated by its power series near 0 and by the
stable upward recursion E_n = (e^{it} - n E_{n-1}) / (i t) elsewhere, so every quantity and every
derivative is finite and smooth across k = 0 (no sin(kd)/k).

Derivatives are first taken in the intermediate variables y = [d_0, d_1, d_2, Theta_0, Theta_1,
Theta_2], where they follow one closed-form rule (``term_mono``): d^n/dTheta^n E_0(t) = i^n E_n(t),
and derivatives of exp(i phi_{j-1}) in any earlier Theta give a factor i.  The chain rule to
q = [d, k] (Theta = k d) is then exact: B = dy/dq is sparse and d^2 Theta_j/(dd_j dk_j) = 1.

All functions in this module are written in the numba-compatible subset of numpy (loops, no
Python objects): `harness.fast` compiles them unchanged.  They allocate nothing they return;
callers pass output arrays.
"""

from __future__ import annotations

import numpy as np

IPOW = np.array([1.0 + 0.0j, 0.0 + 1.0j, -1.0 + 0.0j, 0.0 - 1.0j])  # i**n for n mod 4
SERIES_RADIUS = 2.0  # |t| below which E_n uses the power series (24 terms: error < 1e-16)
INV = 1.0 / np.arange(1.0, 33.0)  # INV[k] = 1 / (k + 1)


def en_tuple(t):
    """(E_0, E_1, E_2, E_3)(t), E_n(t) = int_0^1 v^n exp(i t v) dv, as a tuple of complex.

    Real arithmetic, no allocation: the series term (i t)^m / m! is i^m a_m with a_m = t^m / m!
    real (divisions replaced by the reciprocal table INV), and dividing by i t is a swap and a sign."""
    if abs(t) < SERIES_RADIUS:
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        r3 = 0.0
        i0 = 0.0
        i1 = 0.0
        i2 = 0.0
        i3 = 0.0
        a = 1.0  # t^m / m!
        for m in range(26):
            v0 = a * INV[m]
            v1 = a * INV[m + 1]
            v2 = a * INV[m + 2]
            v3 = a * INV[m + 3]
            q = m & 3
            if q == 0:
                r0 += v0
                r1 += v1
                r2 += v2
                r3 += v3
            elif q == 1:
                i0 += v0
                i1 += v1
                i2 += v2
                i3 += v3
            elif q == 2:
                r0 -= v0
                r1 -= v1
                r2 -= v2
                r3 -= v3
            else:
                i0 -= v0
                i1 -= v1
                i2 -= v2
                i3 -= v3
            a = a * t * INV[m]
            if abs(a) < 1e-18:
                break
        return complex(r0, i0), complex(r1, i1), complex(r2, i2), complex(r3, i3)
    c = np.cos(t)
    s = np.sin(t)
    # E_0 = (e - 1) / (i t);  E_n = (e - n E_{n-1}) / (i t);  z / (i t) = (Im z - i Re z) / t
    r0 = s / t
    i0 = -(c - 1.0) / t
    r1 = (s - i0) / t
    i1 = -(c - r0) / t
    r2 = (s - 2.0 * i1) / t
    i2 = -(c - 2.0 * r1) / t
    r3 = (s - 3.0 * i2) / t
    i3 = -(c - 3.0 * r2) / t
    return complex(r0, i0), complex(r1, i1), complex(r2, i2), complex(r3, i3)


def en_values(t, out):
    """E_n(t) = int_0^1 v^n exp(i t v) dv for n = 0..3 into out, complex (4,)."""
    e0, e1, e2, e3 = en_tuple(t)
    out[0] = e0
    out[1] = e1
    out[2] = e2
    out[3] = e3


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


def term_bases(u, thj, f):
    """b_n = f u^(1+n) E_n(u Theta_j), n = 0..3, f = exp(i phi_prev) (phi_prev: angle at the start of
    section j): every derivative of T_j(u) is i^(npre+nt) b_nt, times d_j if it is not
    differentiated in d_j (see term_mono)."""
    e0, e1, e2, e3 = en_tuple(u * thj)
    u2 = u * u
    u3 = u2 * u
    u4 = u3 * u
    return f * (u * e0), f * (u2 * e1), f * (u3 * e2), f * (u4 * e3)


def tval(npre, nd, nt, dj, b0, b1, b2, b3):
    """term_mono(npre, nd, nt) from the bases b_n of term_bases (0 for nd >= 2)."""
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


def term_mono(fj, npre, nd, nt, u, dj, E):
    """Derivative of T_j(u) = f_j u d_j E_0(u Theta_j) taken npre times in earlier angles, nd times
    in d_j and nt times in Theta_j (E = E_n(u Theta_j), n = 0..3)."""
    if nd >= 2:
        return 0.0j
    val = fj * IPOW[(npre + nt) % 4] * u ** (1 + nt) * E[nt]
    if nd == 0:
        val = val * dj
    return val


def ty_acc(j, npre, nd, nt, ydot, dj, b0, b1, b2, b3):
    """sum_w ydot_w term_mono(derivative (npre, nd, nt) of T_j, once more in y_w), w in order."""
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


def term_grad_add(j, dj, b0, b1, Jy):
    """Add the y-gradient of T_j (bases b0, b1 from term_bases) to Jy (6,) complex."""
    v = complex(-b0.imag, b0.real) * dj  # i b0 d_j: each earlier angle
    for ll in range(j):
        Jy[3 + ll] += v
    Jy[j] += b0
    Jy[3 + j] += complex(-b1.imag, b1.real) * dj  # i b1 d_j


def term_ydd(j, dj, ydot, b0, b1, b2):
    """ydot^T (d^2 T_j / dy^2) ydot (complex): with P = sum of the earlier angle rates, D = ydot[d_j],
    W = ydot[Theta_j]:  -P^2 b0 d_j + 2 P D i b0 - 2 P W b1 d_j + 2 D W i b1 - W^2 b2 d_j."""
    P = 0.0
    for ll in range(j):
        P += ydot[3 + ll]
    D = ydot[j]
    W = ydot[3 + j]
    ib0 = complex(-b0.imag, b0.real)
    ib1 = complex(-b1.imag, b1.real)
    return -(P * P * dj) * b0 + (2.0 * P * D) * ib0 - (2.0 * P * W * dj) * b1 + (2.0 * D * W) * ib1 \
        - (W * W * dj) * b2


def term_y_derivs(j, u, d, th, phi_prev, order, ydot, c, Jy, Hy, Ty):
    """Accumulate T_j(u) and its y-derivatives into c (1,), Jy (6,), Hy (6,6), Ty (6,6) (complex).

    order 0: value; 1: + gradient; 2: + Hessian; 3: + third derivative contracted with ydot (6,).
    phi_prev: angle at the start of section j (sum of earlier Theta).  Every derivative is
    term_mono(npre, nd, nt) (see there): the variables of T_j play three roles, earlier angles
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


def y_of_q(q, d, th, ydot, dq):
    """Split q = [d, k] into d (3,), Theta (3,) and ydot = dy/dt (6,) (dq may be zeros)."""
    for i in range(3):
        d[i] = q[i]
        th[i] = q[3 + i] * q[i]
        ydot[i] = dq[i]
        ydot[3 + i] = q[3 + i] * dq[i] + q[i] * dq[3 + i]


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


def backbone_points(q, n_per_section, out):
    """Backbone points [X, Z] at n_per_section + 1 evenly spaced material points per section
    (shared section ends counted once): out (3 n + 1, 2), m."""
    base = 0.0j
    phi = 0.0
    out[0, 0] = 0.0
    out[0, 1] = 0.0
    r = 1
    for s in range(3):
        ds = q[s]
        ths = q[3 + s] * ds
        f = complex(np.cos(phi), np.sin(phi))
        for m in range(1, n_per_section + 1):
            u = m / n_per_section
            p = base + f * u * ds * en_tuple(u * ths)[0]
            out[r, 0] = p.imag
            out[r, 1] = p.real
            r += 1
        base = base + f * ds * en_tuple(ths)[0]
        phi += ths


def gram_terms(J, Jd, out):
    """A = J J^T and dA/dt = dJ J^T + J dJ^T for a 2x6 J: out = [A00, A01, A11, dA00, dA01, dA11]."""
    for r in range(6):
        out[r] = 0.0
    for a in range(6):
        out[0] += J[0, a] * J[0, a]
        out[1] += J[0, a] * J[1, a]
        out[2] += J[1, a] * J[1, a]
        out[3] += 2.0 * Jd[0, a] * J[0, a]
        out[4] += Jd[0, a] * J[1, a] + J[0, a] * Jd[1, a]
        out[5] += 2.0 * Jd[1, a] * J[1, a]


KERNELS = (
    "gram_terms", "en_tuple", "en_values", "ipow_mul", "term_bases", "tval", "ty_acc", "term_grad_add",
    "term_ydd", "term_mono", "term_y_derivs", "chain_nz", "y_of_q", "chain_to_q",
    "chain_to_q_dot", "point_y_derivs", "backbone_points", "add_role_blocks",
)
