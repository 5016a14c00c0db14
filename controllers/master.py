"""Analytic model of the planar 2-link revolute master (paper Sec. II-C, VI): q1 = [q_a, q_b] (rad) from
+Z toward +X, x1 = [X, Z] = [l1 sin q_a + l2 sin(q_a + q_b), l1 cos q_a + l2 cos(q_a + q_b)] (m);
uniform links, gravity along -Z, optional viscous joint friction.
"""

from __future__ import annotations

import numpy as np

from .params import MasterParams


def packed(p: MasterParams) -> np.ndarray:
    """Packed parameters [l1, l2, m1, m2, I1, I2, b1, b2, g] for the kernels."""
    return np.array([*p.lengths, *p.masses, *p.inertias, *p.damping, p.gravity], dtype=np.float64)


def master_kernel(pk, q, dq, x, J, Jd, M, N):
    """From q, dq (2,): x (2,) tip, J (2,2), Jd (2,2) = dJ/dt, M (2,2), N (2,) = C dq + G + B dq."""
    l1, l2, m1, m2, I1, I2, b1, b2, g = pk[0], pk[1], pk[2], pk[3], pk[4], pk[5], pk[6], pk[7], pk[8]
    s1, c1 = np.sin(q[0]), np.cos(q[0])
    s12, c12 = np.sin(q[0] + q[1]), np.cos(q[0] + q[1])
    s2, c2 = np.sin(q[1]), np.cos(q[1])
    w1, w12 = dq[0], dq[0] + dq[1]
    x[0] = l1 * s1 + l2 * s12
    x[1] = l1 * c1 + l2 * c12
    J[0, 0] = l1 * c1 + l2 * c12
    J[0, 1] = l2 * c12
    J[1, 0] = -l1 * s1 - l2 * s12
    J[1, 1] = -l2 * s12
    Jd[0, 0] = -l1 * s1 * w1 - l2 * s12 * w12
    Jd[0, 1] = -l2 * s12 * w12
    Jd[1, 0] = -l1 * c1 * w1 - l2 * c12 * w12
    Jd[1, 1] = -l2 * c12 * w12
    lc1, lc2 = 0.5 * l1, 0.5 * l2
    M[0, 0] = I1 + I2 + m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * c2)
    M[0, 1] = I2 + m2 * (lc2 * lc2 + l1 * lc2 * c2)
    M[1, 0] = M[0, 1]
    M[1, 1] = I2 + m2 * lc2 * lc2
    h = m2 * l1 * lc2 * s2
    # Coriolis/centripetal (Christoffel), gravity (V = g [m1 lc1 c1 + m2 (l1 c1 + lc2 c12)]), friction
    N[0] = (-h * (2.0 * dq[0] * dq[1] + dq[1] * dq[1]) - g * ((m1 * lc1 + m2 * l1) * s1 + m2 * lc2 * s12)
            + b1 * dq[0])
    N[1] = h * dq[0] * dq[0] - g * m2 * lc2 * s12 + b2 * dq[1]


def master_accel(pk, s, T1, F1, acc):
    """Forward dynamics, eq. (1) i = 1: acc (4,) = d/dt s of s (4,) = [q1, dq1] under T1 (2,) N m and the
    tip force F1 (2,) N (Cramer's rule).  False if M1 is singular (compiled by the Cosserat plant)."""
    x, J, Jd, M, N = np.empty(2), np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2)), np.empty(2)
    master_kernel(pk, s[0:2], s[2:4], x, J, Jd, M, N)
    r0 = T1[0] - N[0] + J[0, 0] * F1[0] + J[1, 0] * F1[1]
    r1 = T1[1] - N[1] + J[0, 1] * F1[0] + J[1, 1] * F1[1]
    det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    if not det > 0.0:
        return False
    acc[0], acc[1] = s[2], s[3]
    acc[2] = (M[1, 1] * r0 - M[0, 1] * r1) / det
    acc[3] = (M[0, 0] * r1 - M[1, 0] * r0) / det
    return True


def master_points(pk, m, base, out):
    """Base, elbow and tip, world frame, out (n, 3, 3) m, of the states m (n, >= 2) [q1, ...] with the
    base at base (3,) (task [X, Z] -> world (b_x + X, b_y, b_z + Z))."""
    l1, l2 = pk[0], pk[1]
    for k in range(m.shape[0]):
        q0, q1 = m[k, 0], m[k, 1]
        out[k] = base
        out[k, 1, 0] += l1 * np.sin(q0)
        out[k, 1, 2] += l1 * np.cos(q0)
        out[k, 2, 0] = out[k, 1, 0] + l2 * np.sin(q0 + q1)
        out[k, 2, 2] = out[k, 1, 2] + l2 * np.cos(q0 + q1)


KERNELS = ("master_kernel",)  # master_accel and master_points: compiled where used (the Cosserat plant)


def _eval(p: MasterParams, q, dq=None):
    """(x1 (2,) m, J1 (2,2), dJ1/dt (2,2), M1 (2,2) kg m^2, N1 (2,) N m) at q1, dq1 (default 0)."""
    q = np.asarray(q, dtype=float)
    dq = np.zeros(2) if dq is None else np.asarray(dq, dtype=float)
    out = np.empty(2), np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2)), np.empty(2)
    master_kernel(packed(p), q, dq, *out)
    return out


def fk(p: MasterParams, q) -> np.ndarray:
    """Tip x1 = [X, Z] (2,), m."""
    return _eval(p, q)[0]


def jacobian(p: MasterParams, q) -> np.ndarray:
    """J1 = dx1/dq1 (2, 2)."""
    return _eval(p, q)[1]


def jacobian_dot(p: MasterParams, q, dq) -> np.ndarray:
    """dJ1/dt (2, 2)."""
    return _eval(p, q, dq)[2]


def mass_matrix(p: MasterParams, q) -> np.ndarray:
    """M1(q1) (2, 2), kg m^2."""
    return _eval(p, q)[3]


def nle(p: MasterParams, q, dq) -> np.ndarray:
    """N1(q1, dq1) (2,) = Coriolis/centripetal + gravity + viscous friction, N m."""
    return _eval(p, q, dq)[4]


def gravity_force(p: MasterParams, q) -> np.ndarray:
    """dV/dq1 (2,), N m (N1 at rest)."""
    return _eval(p, q)[4]


def ik(p: MasterParams, x, elbow: int = -1) -> np.ndarray:
    """Joint angles reaching x = [X, Z] (2,); elbow = sign of q_b.  Raises ValueError if unreachable."""
    X, Z = float(x[0]), float(x[1])
    l1, l2 = p.lengths
    r2 = X * X + Z * Z
    cb = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    if not -1.0 <= cb <= 1.0:
        raise ValueError(
            f"master target [{X:.4f}, {Z:.4f}] m is unreachable: distance {np.sqrt(r2):.4f} m outside "
            f"[{abs(l1 - l2):.4f}, {l1 + l2:.4f}] m")
    qb = float(np.sign(elbow) or 1.0) * np.arccos(cb)
    # angle of the target from +Z toward +X, minus the elbow contribution
    qa = np.arctan2(X, Z) - np.arctan2(l2 * np.sin(qb), l1 + l2 * np.cos(qb))
    return np.array([qa, qb])
