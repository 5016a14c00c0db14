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


def en_values(t, out):
    """E_n(t) = int_0^1 v^n exp(i t v) dv for n = 0..3 into out, complex (4,)."""
    if abs(t) < SERIES_RADIUS:
        for n in range(4):
            out[n] = 0.0
        term = 1.0 + 0.0j  # (i t)^m / m!
        for m in range(26):
            for n in range(4):
                out[n] += term / (n + m + 1)
            term = term * (1j * t) / (m + 1)
            if abs(term) < 1e-18:
                break
    else:
        e = complex(np.cos(t), np.sin(t))
        it = 1j * t
        out[0] = (e - 1.0) / it
        for n in range(1, 4):
            out[n] = (e - n * out[n - 1]) / it


def vtype(j, v):
    """Role of intermediate variable y_v in term T_j: 0 none, 1 earlier angle, 2 d_j, 3 Theta_j."""
    if v < 3:
        return 2 if v == j else 0
    s = v - 3
    if s < j:
        return 1
    if s == j:
        return 3
    return 0


def term_mono(fj, npre, nd, nt, u, dj, E):
    """Derivative of T_j(u) = f_j u d_j E_0(u Theta_j) taken npre times in earlier angles, nd times
    in d_j and nt times in Theta_j (E = E_n(u Theta_j), n = 0..3)."""
    if nd >= 2:
        return 0.0j
    val = fj * IPOW[(npre + nt) % 4] * u ** (1 + nt) * E[nt]
    if nd == 0:
        val = val * dj
    return val


def term_table(fj, u, dj, E, tab):
    """tab[npre, nd, nt] = term_mono(fj, npre, nd, nt, u, dj, E) for npre, nt in 0..3, nd in 0..1
    (derivatives of order > 3 are never used)."""
    up = 1.0
    for nt in range(4):
        up = up * u  # u^(1+nt)
        base = up * E[nt]
        for npre in range(4 - nt):
            v = fj * IPOW[(npre + nt) % 4] * base
            tab[npre, 0, nt] = v * dj
            tab[npre, 1, nt] = v


def term_y_derivs(j, u, d, th, phi_prev, order, ydot, c, Jy, Hy, Ty):
    """Accumulate T_j(u) and its y-derivatives into c (1,), Jy (6,), Hy (6,6), Ty (6,6) (complex).

    order 0: value; 1: + gradient; 2: + Hessian; 3: + third derivative contracted with ydot (6,).
    phi_prev: angle at the start of section j (sum of earlier Theta).  Every derivative is a table
    entry term_mono(npre, nd, nt) (see there), computed once per call.
    """
    E = np.empty(4, dtype=np.complex128)
    en_values(u * th[j], E)
    fj = complex(np.cos(phi_prev), np.sin(phi_prev))
    tab = np.zeros((4, 2, 4), dtype=np.complex128)
    term_table(fj, u, d[j], E, tab)
    c[0] += tab[0, 0, 0]
    if order < 1:
        return
    # relevant variables of term j: earlier angles 3..3+j-1 (type 1), d_j (2), Theta_j (3)
    for a in range(6):
        ta = vtype(j, a)
        if ta == 0:
            continue
        pa = int(ta == 1)
        da = int(ta == 2)
        na = int(ta == 3)
        Jy[a] += tab[pa, da, na]
        if order < 2:
            continue
        for b in range(6):
            tb = vtype(j, b)
            if tb == 0:
                continue
            npre = pa + int(tb == 1)
            nd = da + int(tb == 2)
            nt = na + int(tb == 3)
            if nd >= 2:
                continue
            Hy[a, b] += tab[npre, nd, nt]
            if order < 3:
                continue
            acc = 0.0j
            for w in range(6):
                tw = vtype(j, w)
                if tw == 0 or ydot[w] == 0.0:
                    continue
                ndw = nd + int(tw == 2)
                if ndw >= 2:
                    continue
                acc += ydot[w] * tab[npre + int(tw == 1), ndw, nt + int(tw == 3)]
            Ty[a, b] += acc


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


def tip_kinematics(q, dq, order, x, J, H, Hd):
    """Tip of the 3-section arm and its q-derivatives, as real arrays in [X, Z] rows.

    q, dq: (6,) [d (m), k (1/m)] and rates.  x (2,) m; J (2,6) = dx/dq; H (2,6,6) = d^2x/dq^2
    (order >= 2); Hd (2,6,6) = dH/dt along dq (order >= 3).  J2dot = H . dq.
    """
    d = np.empty(3)
    th = np.empty(3)
    ydot = np.empty(6)
    y_of_q(q, d, th, ydot, dq)
    c = np.zeros(1, dtype=np.complex128)
    Jy = np.zeros(6, dtype=np.complex128)
    Hy = np.zeros((6, 6), dtype=np.complex128)
    Ty = np.zeros((6, 6), dtype=np.complex128)
    point_y_derivs(2, 1.0, d, th, order, ydot, c, Jy, Hy, Ty)
    x[0] = c[0].imag
    x[1] = c[0].real
    if order < 1:
        return
    nzu = np.empty((6, 2), dtype=np.int64)
    nzb = np.empty((6, 2))
    nzbd = np.empty((6, 2))
    chain_nz(q, dq, nzu, nzb, nzbd)
    Jq = np.empty(6, dtype=np.complex128)
    Hq = np.empty((6, 6), dtype=np.complex128)
    Hqd = np.empty((6, 6), dtype=np.complex128)
    chain_to_q(order, Jy, Hy, Ty, nzu, nzb, nzbd, Jq, Hq, Hqd)
    for a in range(6):
        J[0, a] = Jq[a].imag
        J[1, a] = Jq[a].real
    if order < 2:
        return
    for a in range(6):
        for b in range(6):
            H[0, a, b] = Hq[a, b].imag
            H[1, a, b] = Hq[a, b].real
    if order < 3:
        return
    chain_to_q_dot(Jy, Hy, Ty, ydot, nzu, nzb, nzbd, Hqd)
    for a in range(6):
        for b in range(6):
            Hd[0, a, b] = Hqd[a, b].imag
            Hd[1, a, b] = Hqd[a, b].real


def backbone_points(q, n_per_section, out):
    """Backbone points [X, Z] at n_per_section + 1 evenly spaced material points per section
    (shared section ends counted once): out (3 n + 1, 2), m."""
    d = np.empty(3)
    th = np.empty(3)
    for i in range(3):
        d[i] = q[i]
        th[i] = q[3 + i] * q[i]
    E = np.empty(4, dtype=np.complex128)
    base = 0.0j
    phi = 0.0
    out[0, 0] = 0.0
    out[0, 1] = 0.0
    r = 1
    for s in range(3):
        f = complex(np.cos(phi), np.sin(phi))
        for m in range(1, n_per_section + 1):
            u = m / n_per_section
            en_values(u * th[s], E)
            p = base + f * u * d[s] * E[0]
            out[r, 0] = p.imag
            out[r, 1] = p.real
            r += 1
        en_values(th[s], E)
        base = base + f * d[s] * E[0]
        phi += th[s]


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
    "gram_terms", "en_values", "vtype", "term_mono", "term_table", "term_y_derivs", "chain_nz", "y_of_q",
    "chain_to_q", "chain_to_q_dot", "point_y_derivs", "tip_kinematics", "backbone_points",
)
