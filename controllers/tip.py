"""Tip of the 3-section CC arm and its exact q-derivatives to third order per control step (x2, J2,
dJ2/dt, H = d^2 x2/dq2^2 and dH/dt for (27)); representation as `controllers.cc`; tails R_j = sum_{m >= j}
d_m f_m E_0(Theta_m) give dc/dTheta_l = i (R_{l+1} + d_l f_l E_1(Theta_l)).
"""

from __future__ import annotations

from .cc import en_tuple
from .scratch import scratch_c


def tip_bases(q, b, R):
    """b (3, 4) complex: b[j, n] = f_j E_n(Theta_j), f_j = exp(i phi_j) the tangent at the start of
    section j; tails R (4,) complex: R[j] = sum_{m >= j} d_m b[m, 0] (R[0] = tip, R[3] = 0)."""
    f = 1.0 + 0.0j
    for j in range(3):
        th = q[3 + j] * q[j]
        e0, e1, e2, e3 = en_tuple(th)
        b[j, 0] = f * e0
        b[j, 1] = f * e1
        b[j, 2] = f * e2
        b[j, 3] = f * e3
        f = f * complex(1.0 - th * e0.imag, th * e0.real)
    R[3] = 0.0
    for j in range(2, -1, -1):
        R[j] = R[j + 1] + q[j] * b[j, 0]


def tip_y_blocks(c, G, diag, XdT, XTT):
    """The tip's y-Hessian blocks (y = [d, Theta]; the d-d block is zero) from bases c (b of tip_bases or
    their rates), G (3,) = dc/dTheta and diag (3,) = d^2c/dTheta_j^2 (or their rates):
    XdT (3,3)[j, l] = d^2c/(dd_j dTheta_l) = i c[j, 1] (l = j), i c[j, 0] (l < j), 0 (l > j);
    XTT (3,3) symmetric, d^2c/(dTheta_l dTheta_m) = i G[m] (l < m), diag[m] (l = m)."""
    for j in range(3):
        ic0 = complex(-c[j, 0].imag, c[j, 0].real)
        for m in range(3):
            if m < j:
                XdT[j, m] = ic0
            elif m == j:
                XdT[j, m] = complex(-c[j, 1].imag, c[j, 1].real)
            else:
                XdT[j, m] = 0.0
        XTT[j, j] = diag[j]
        for m in range(j + 1, 3):
            v = complex(-G[m].imag, G[m].real)
            XTT[j, m] = v
            XTT[m, j] = v


def put_sym(X, a, b, v):
    """X[:, a, b] = X[:, b, a] = [Im v, Re v] (X (2,6,6): [X, Z] rows of a symmetric q-derivative)."""
    X[0, a, b], X[1, a, b] = v.imag, v.real
    X[0, b, a], X[1, b, a] = v.imag, v.real


def tip_kinematics(q, dq, order, x, J, H, Hd):
    """Tip and its q-derivatives in [X, Z] rows: q, dq (6,); x (2,) m; J (2,6) (order >= 1);
    H (2,6,6) = d^2x/dq^2 (order >= 2); Hd (2,6,6) = dH/dt along dq (order >= 3).  J2dot = H . dq.
    Chain rule y -> q (Theta_i = k_i d_i; dH/dt by the product rule):
        H[d_i, d_j] = k_j XdT[i, j] + k_i XdT[j, i] + k_i k_j XTT[i, j]
        H[d_i, k_j] = d_j (XdT[i, j] + k_i XTT[i, j]) + [i = j] G[i]
        H[k_i, k_j] = d_i d_j XTT[i, j]."""
    b, R = scratch_c((3, 4)), scratch_c(4)
    tip_bases(q, b, R)
    x[0], x[1] = R[0].imag, R[0].real
    if order < 1:
        return
    G = scratch_c(3)
    for i in range(3):
        v = R[i + 1] + q[i] * b[i, 1]
        G[i] = complex(-v.imag, v.real)  # dc/dTheta_i (dc/dd_i = b[i, 0])
        jd = b[i, 0] + q[3 + i] * G[i]
        jk = q[i] * G[i]
        J[0, i], J[1, i] = jd.imag, jd.real
        J[0, 3 + i], J[1, 3 + i] = jk.imag, jk.real
    if order < 2:
        return
    XdT, XTT, diag = scratch_c((3, 3)), scratch_c((3, 3)), scratch_c(3)
    for i in range(3):
        diag[i] = -(R[i + 1] + q[i] * b[i, 2])
    tip_y_blocks(b, G, diag, XdT, XTT)
    if order >= 3:
        # rates: Thetadot, phidot, db/dt (n = 0..2), the tails' rates Rd, and Gd = dG/dt
        bd, Rd, Gd = scratch_c((3, 3)), scratch_c(4), scratch_c(3)
        YdT, YTT = scratch_c((3, 3)), scratch_c((3, 3))
        phid = 0.0
        for j in range(3):
            thd = q[3 + j] * dq[j] + q[j] * dq[3 + j]  # dTheta_j/dt
            for n in range(3):
                v = phid * b[j, n] + thd * b[j, n + 1]
                bd[j, n] = complex(-v.imag, v.real)
            phid += thd
        Rd[3] = 0.0
        for j in range(2, -1, -1):
            Rd[j] = Rd[j + 1] + dq[j] * b[j, 0] + q[j] * bd[j, 0]
        diagd = scratch_c(3)
        for i in range(3):
            v = Rd[i + 1] + dq[i] * b[i, 1] + q[i] * bd[i, 1]
            Gd[i] = complex(-v.imag, v.real)
            diagd[i] = -(Rd[i + 1] + dq[i] * b[i, 2] + q[i] * bd[i, 2])
        tip_y_blocks(bd, Gd, diagd, YdT, YTT)
    for i in range(3):
        di, ki = q[i], q[3 + i]
        for j in range(3):
            dj, kj = q[j], q[3 + j]
            xt = XTT[i, j]
            hdk = dj * (XdT[i, j] + ki * xt)
            if i == j:
                hdk += G[i]
            put_sym(H, i, 3 + j, hdk)
            if j >= i:
                hdd = kj * XdT[i, j] + ki * XdT[j, i] + (ki * kj) * xt
                hkk = (di * dj) * xt
                put_sym(H, i, j, hdd)
                put_sym(H, 3 + i, 3 + j, hkk)
            if order < 3:
                continue
            ddi, kdi = dq[i], dq[3 + i]
            ddj, kdj = dq[j], dq[3 + j]
            yt = YTT[i, j]
            gdk = (ddj * (XdT[i, j] + ki * xt)
                   + dj * (YdT[i, j] + kdi * xt + ki * yt))
            if i == j:
                gdk += Gd[i]
            put_sym(Hd, i, 3 + j, gdk)
            if j >= i:
                gdd = (kj * YdT[i, j] + ki * YdT[j, i] + (ki * kj) * yt
                       + kdj * XdT[i, j] + kdi * XdT[j, i] + (kdi * kj + ki * kdj) * xt)
                gkk = (ddi * dj + di * ddj) * xt + (di * dj) * yt
                put_sym(Hd, i, j, gdd)
                put_sym(Hd, 3 + i, 3 + j, gkk)


KERNELS = ("tip_bases", "tip_y_blocks", "put_sym", "tip_kinematics")
