"""Null-space sub-tasks, paper Sec. V, eqs. (29)-(33), (41): y_a = exp(-ky beta), g = ks ky y_a^2 grad beta,
beta = sum_j w_j beta_j of ``manipulability`` beta_m = sqrt(det(J2 J2^T)) (41) and ``limits`` beta_l =
sum_j (1 - s_j^(2p)), s_j in [-1, 1] the normalised section lengths and bend angles k d / bmax; each with
grad beta and d/dt grad beta in closed form.  Packed spec = [w_manip, w_limits, p, e, bmax, L0 (3)].
"""

from __future__ import annotations

import numpy as np

from .cc import gram_terms
from .params import SlaveParams, SubtaskSpec
from .scratch import scratch
from .slave import jacobian, tip_derivatives

SPEC_SIZE = 8


def pack_subtask(spec: SubtaskSpec, slave: SlaveParams) -> np.ndarray:
    """Packed sub-task description [w_manip, w_limits, p, max_extension, max_bend, L0 (3)]."""
    w = dict(zip(spec.kinds, spec.weights, strict=True))
    return np.array([w.get("manipulability", 0.0), w.get("limits", 0.0), float(spec.limit_power),
                     slave.max_extension, slave.max_bend, *slave.rest_lengths], dtype=np.float64)


def manipulability_kernel(J, H, Jd, Hd, grad, graddot):
    """beta_m = sqrt(det A), A = J J^T; writes grad, graddot (6,).  J, Jd (2,6) = dJ/dt, H, Hd (2,6,6) =
    dJ/dq and its rate.  Returns (beta, det A)."""
    gt = scratch(6)
    gram_terms(J, Jd, gt)
    A00, A01, A11, Ad00, Ad01, Ad11 = gt[0], gt[1], gt[2], gt[3], gt[4], gt[5]
    det = A00 * A11 - A01 * A01
    if det <= 0.0:
        for c in range(6):
            grad[c] = graddot[c] = 0.0
        return 0.0, det
    beta = np.sqrt(det)
    detd = Ad00 * A11 + A00 * Ad11 - 2.0 * A01 * Ad01
    betad = detd / (2.0 * beta)
    for c in range(6):
        # dA/dq_c = H_c J^T + J H_c^T and its time derivative
        dA00 = dA01 = dA11 = dAd00 = dAd01 = dAd11 = 0.0
        for a in range(6):
            h0, h1 = H[0, a, c], H[1, a, c]
            hd0, hd1 = Hd[0, a, c], Hd[1, a, c]
            dA00 += 2.0 * h0 * J[0, a]
            dA01 += h0 * J[1, a] + J[0, a] * h1
            dA11 += 2.0 * h1 * J[1, a]
            dAd00 += 2.0 * (hd0 * J[0, a] + h0 * Jd[0, a])
            dAd01 += hd0 * J[1, a] + h0 * Jd[1, a] + Jd[0, a] * h1 + J[0, a] * hd1
            dAd11 += 2.0 * (hd1 * J[1, a] + h1 * Jd[1, a])
        ddet = dA00 * A11 + A00 * dA11 - 2.0 * A01 * dA01
        ddetd = (dAd00 * A11 + dA00 * Ad11 + Ad00 * dA11 + A00 * dAd11
                 - 2.0 * (Ad01 * dA01 + A01 * dAd01))
        grad[c] = ddet / (2.0 * beta)
        graddot[c] = ddetd / (2.0 * beta) - ddet * betad / (2.0 * beta * beta)
    return beta, det


def limit_powers(s, p2):
    """(s^(p2-2), s^(p2-1), s^p2); an integer p2 >= 2 by binary powering."""
    n = int(p2)
    if n == p2 and n >= 2:
        a, b, e = 1.0, s, n - 2
        while e > 0:
            if e & 1:
                a *= b
            b *= b
            e >>= 1
        a1 = a * s
        return a, a1, a1 * s
    return s ** (p2 - 2.0), s ** (p2 - 1.0), s ** p2


def limits_kernel(spec, q, dq, grad, graddot):
    """beta_l = sum (1 - s^(2p)) over 3 lengths and 3 bending angles; grad and d/dt grad (6,)."""
    p2, ext, bmax = 2.0 * spec[2], spec[3], spec[4]
    beta = 0.0
    for c in range(6):
        grad[c] = graddot[c] = 0.0
    for i in range(3):
        L0 = spec[5 + i]
        cen, hw = 0.5 * L0 * (1.0 + ext), 0.5 * L0 * (ext - 1.0)
        # length coordinate
        s, sd = (q[i] - cen) / hw, dq[i] / hw
        sm2, sm1, sp = limit_powers(s, p2)
        beta += 1.0 - sp
        grad[i] += -p2 * sm1 / hw
        graddot[i] += -p2 * (p2 - 1.0) * sm2 * sd / hw
        # bending angle coordinate s = k d / bmax
        s = q[3 + i] * q[i] / bmax
        sd = (dq[3 + i] * q[i] + q[3 + i] * dq[i]) / bmax
        sm2, sm1, sp = limit_powers(s, p2)
        beta += 1.0 - sp
        f = -p2 * sm1
        fd = -p2 * (p2 - 1.0) * sm2 * sd
        # ds/dd = k / bmax, ds/dk = d / bmax
        grad[i] += f * q[3 + i] / bmax
        grad[3 + i] += f * q[i] / bmax
        graddot[i] += (fd * q[3 + i] + f * dq[3 + i]) / bmax
        graddot[3 + i] += (fd * q[i] + f * dq[i]) / bmax
    return beta


def subtask_kernel(spec, J, H, Jd, Hd, q, dq, grad, graddot, parts):
    """Combined beta = w_m beta_m + w_l beta_l with grad and d/dt grad (6,) (overwritten).
    parts (3,) receives [beta_m, beta_l, det(J J^T)].  Returns beta."""
    g1, gd1 = scratch(6), scratch(6)
    beta_m, det = manipulability_kernel(J, H, Jd, Hd, g1, gd1)
    parts[0], parts[2] = beta_m, det
    beta = spec[0] * beta_m
    for c in range(6):
        grad[c] = spec[0] * g1[c]
        graddot[c] = spec[0] * gd1[c]
    parts[1] = 0.0
    if spec[1] != 0.0:
        beta_l = limits_kernel(spec, q, dq, g1, gd1)
        parts[1] = beta_l
        beta += spec[1] * beta_l
        for c in range(6):
            grad[c] += spec[1] * g1[c]
            graddot[c] += spec[1] * gd1[c]
    return beta


KERNELS = ("manipulability_kernel", "limit_powers", "limits_kernel", "subtask_kernel")


def beta(spec: SubtaskSpec, slave: SlaveParams, q, dq=None) -> tuple[float, np.ndarray, np.ndarray]:
    """(beta, grad beta (6,), d/dt grad beta (6,)) of the combined sub-task at q2, dq2."""
    q = np.ascontiguousarray(q, dtype=float)
    dq = np.zeros(6) if dq is None else np.ascontiguousarray(dq, dtype=float)
    x, J, H, Hd = tip_derivatives(slave, q, dq)
    Jd = np.einsum("iab,b->ia", H, dq)
    grad, graddot, parts = np.empty(6), np.empty(6), np.empty(3)
    b = subtask_kernel(pack_subtask(spec, slave), J, H, Jd, Hd, q, dq, grad, graddot, parts)
    return float(b), grad, graddot


def manipulability(slave: SlaveParams, q) -> float:
    """Paper eq. (41): sqrt(det(J2 J2^T))."""
    J = jacobian(slave, q)
    return float(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)))
