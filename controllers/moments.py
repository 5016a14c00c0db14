"""Per-section quadrature moments of `slave.mass_nle_kernel` as power series in the bend angle Theta,
tabulated once per Gauss-Legendre rule (the same sums, regrouped); mu_j = sum_g w_g u_g^j:

    Q[0, n+1]   = sum_g w_g b_n(u_g)                =  f sum_p (i Theta)^p a_{n,p} mu_{p+n+1}
    Q[k+1, l+1] = sum_g w_g conj(b_k(u_g)) b_l(u_g) =    sum_p (i Theta)^p c_{kl,p} mu_{p+k+l+2}

a_{n,p} = 1 / (p! (p+n+1)), c_{kl,p} = sum_{m=0..p} (-1)^m / (m! (m+k+1) (p-m)! (p-m+l+1)).
"""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np

from .scratch import scratch, scratch_zeros

MOMENT_RADIUS = 1.5  # rad, |Theta| up to which the series is used
P_MAX = 36  # powers of Theta tabulated (the term at p = 36 is < 1.5^36 / 36! ~ 5e-36 at the radius)
N_RULES = 32  # Gauss-Legendre rules tabulated: n = 2..32 points (slave.n_quad's range)
TAIL = 1e-20  # the series stops once |Theta|^p max_moment |coef_p| drops below this (the moments are >= 1e-3)
# the eight moments: (k, l) of conj(b_k) b_l, or (-1, n) for b_n alone
MOMENTS = ((-1, 0), (-1, 1), (-1, 2), (0, 0), (0, 1), (0, 2), (1, 1), (1, 2))


def gauss_legendre01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights (n,) each on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _rules() -> tuple[np.ndarray, np.ndarray]:
    """NODE0[n]: the first node of the n-point rule on [0, 1]; MU[n, j] = sum_g w_g u_g^j."""
    node0 = np.full(N_RULES + 1, np.nan)
    mu = np.zeros((N_RULES + 1, P_MAX + 8))  # j = p + k + l + 2 <= (P_MAX + 2) + 3 + 2
    for n in range(2, N_RULES + 1):
        u, w = gauss_legendre01(n)
        node0[n] = u[0]
        mu[n] = [float(np.sum(w * u**j)) for j in range(P_MAX + 8)]
    return node0, mu


def _series_table() -> np.ndarray:
    """COEF[n, q, p]: coefficient of Theta^p in moment q (MOMENTS order), n-point rule, i^p as a sign
    (even p: real part, odd p: imaginary part)."""
    sign = [1, 1, -1, -1]  # i^p = 1, i, -1, -i: the sign of its nonzero part
    coef = np.zeros((N_RULES + 1, len(MOMENTS), P_MAX + 3))
    for q, (k, l) in enumerate(MOMENTS):
        for p in range(P_MAX + 3):
            if k < 0:
                r = Fraction(1, factorial(p) * (p + l + 1))
                j = p + l + 1
            else:
                r = sum(Fraction((-1) ** m, factorial(m) * (m + k + 1) * factorial(p - m) * (p - m + l + 1))
                        for m in range(p + 1))
                j = p + k + l + 2
            coef[:, q, p] = sign[p % 4] * float(r) * MU[:, j]
    return coef


NODE0, MU = _rules()
COEF = _series_table()
# CTAIL[p]: the largest coefficient of any moment and rule at powers >= p (bounds the next terms)
CTAIL = np.maximum.accumulate(np.abs(COEF[2:]).max(axis=(0, 1))[::-1])[::-1].copy()


def section_moments(th, f, nodes, Q):
    """Fill Q[0, 0..3], Q[1, 1..3], Q[2, 2..3] (complex (3, 4)) of a section of bend th (rad) starting
    at direction f = exp(i phi).  False (Q untouched) when |th| > MOMENT_RADIUS or `nodes` is not a
    tabulated rule."""
    n = nodes.shape[0]
    if abs(th) > MOMENT_RADIUS or n < 2 or n > N_RULES or nodes[0] != NODE0[n]:
        return False
    re = scratch(8)
    im = scratch_zeros(8)
    for q in range(8):
        re[q] = COEF[n, q, 0]
    a = abs(th)
    t = 1.0  # th^p
    for p in range(1, P_MAX, 2):
        t *= th  # odd power p: the imaginary parts
        for q in range(8):
            im[q] += t * COEF[n, q, p]
        t *= th  # even power p + 1: the real parts
        for q in range(8):
            re[q] += t * COEF[n, q, p + 1]
        if abs(t) * a * CTAIL[p + 2] < TAIL:  # the terms from p + 2 on (|th| < 1.5 < p: they shrink)
            break
    Q[0, 0] = MU[n, 0]
    for m in range(3):
        Q[0, 1 + m] = f * complex(re[m], im[m])
        Q[1, 1 + m] = complex(re[3 + m], im[3 + m])
    Q[2, 2] = complex(re[6], im[6])
    Q[2, 3] = complex(re[7], im[7])
    return True


KERNELS = ("section_moments",)
