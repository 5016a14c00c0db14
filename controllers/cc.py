"""Planar constant-curvature (CC) kinematics with exact derivatives up to third order.  A point is
c = Z + i X, the tangent at arc angle phi is exp(i phi); section j at material coordinate u in [0, 1]:
c_s(u) = sum_{j<s} T_j(1) + T_s(u), T_j(u) = exp(i phi_{j-1}) u d_j E_0(u Theta_j), Theta_j = k_j d_j,
E_n(t) = int_0^1 v^n exp(i t v) dv; the bases b_n = f u^(1+n) E_n(u Theta) carry every y-derivative.
"""

from __future__ import annotations

import numpy as np

from .scratch import scratch_zeros

SERIES_RADIUS = 2.0  # |t| below which E_n uses the power series (24 terms: error < 1e-16)
INV = 1.0 / np.arange(1.0, 33.0)  # INV[k] = 1 / (k + 1)


def en_tuple(t):
    """(E_0, E_1, E_2, E_3)(t), E_n(t) = int_0^1 v^n exp(i t v) dv (complex), in real arithmetic."""
    if abs(t) < SERIES_RADIUS:
        re, im = scratch_zeros(4), scratch_zeros(4)
        a = 1.0  # t^m / m!
        for m in range(26):
            sa = a if m & 2 == 0 else -a  # i^m a: its sign, and whether it is real (m even)
            if m & 1 == 0:
                for n in range(4):
                    re[n] += sa * INV[m + n]
            else:
                for n in range(4):
                    im[n] += sa * INV[m + n]
            a = a * t * INV[m]
            if abs(a) < 1e-18:
                break
        return complex(re[0], im[0]), complex(re[1], im[1]), complex(re[2], im[2]), complex(re[3], im[3])
    c, s = np.cos(t), np.sin(t)
    # E_0 = (e - 1) / (i t);  E_n = (e - n E_{n-1}) / (i t);  z / (i t) = (Im z - i Re z) / t
    r0, i0 = s / t, -(c - 1.0) / t
    r1, i1 = (s - i0) / t, -(c - r0) / t
    r2, i2 = (s - 2.0 * i1) / t, -(c - 2.0 * r1) / t
    r3, i3 = (s - 3.0 * i2) / t, -(c - 3.0 * r2) / t
    return complex(r0, i0), complex(r1, i1), complex(r2, i2), complex(r3, i3)


def term_bases(u, thj, f):
    """b_n = f u^(1+n) E_n(u Theta_j), n = 0..3, f = exp(i phi) at the start of section j."""
    e0, e1, e2, e3 = en_tuple(u * thj)
    u2 = u * u
    u3 = u2 * u
    u4 = u3 * u
    return f * (u * e0), f * (u2 * e1), f * (u3 * e2), f * (u4 * e3)


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
    D, W = ydot[j], ydot[3 + j]
    ib0, ib1 = complex(-b0.imag, b0.real), complex(-b1.imag, b1.real)
    return -(P * P * dj) * b0 + (2.0 * P * D) * ib0 - (2.0 * P * W * dj) * b1 + (2.0 * D * W) * ib1 \
        - (W * W * dj) * b2


def y_of_q(q, d, th, ydot, dq):
    """Split q = [d, k] into d (3,), Theta (3,) and ydot = dy/dt (6,) (dq may be zeros)."""
    for i in range(3):
        d[i] = q[i]
        th[i] = q[3 + i] * q[i]
        ydot[i] = dq[i]
        ydot[3 + i] = q[3 + i] * dq[i] + q[i] * dq[3 + i]


def backbone_points(q, n_per_section, out):
    """Backbone points [X, Z] (m), out (3 n + 1, 2): base, then n evenly spaced points per section."""
    base, phi = 0.0j, 0.0
    out[0, 0] = out[0, 1] = 0.0
    r = 1
    for s in range(3):
        ds = q[s]
        ths = q[3 + s] * ds
        f = complex(np.cos(phi), np.sin(phi))
        for m in range(1, n_per_section + 1):
            u = m / n_per_section
            p = base + f * u * ds * en_tuple(u * ths)[0]
            out[r, 0], out[r, 1] = p.imag, p.real
            r += 1
        base = base + f * ds * en_tuple(ths)[0]
        phi += ths


def backbone_rows(q2, n_per_section, out):
    """`backbone_points` of every row of q2 (m, 6) into out (m, 3 n + 1, 2), m (the outputs' form)."""
    for k in range(q2.shape[0]):
        backbone_points(q2[k], n_per_section, out[k])


def gram_terms(J, Jd, out):
    """A = J J^T and dA/dt = dJ J^T + J dJ^T for a 2x6 J: out = [A00, A01, A11, dA00, dA01, dA11]."""
    out[:] = 0.0
    for a in range(6):
        out[0] += J[0, a] * J[0, a]
        out[1] += J[0, a] * J[1, a]
        out[2] += J[1, a] * J[1, a]
        out[3] += 2.0 * Jd[0, a] * J[0, a]
        out[4] += Jd[0, a] * J[1, a] + J[0, a] * Jd[1, a]
        out[5] += 2.0 * Jd[1, a] * J[1, a]


KERNELS = ("gram_terms", "en_tuple", "term_bases", "term_grad_add", "term_ydd", "y_of_q", "backbone_points",
           "backbone_rows")
