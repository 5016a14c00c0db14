"""Compiled physics of the planar Octarm Cosserat rod (`harness.plant.cosserat.rod`): loads, position
Verlet steps, the CC fit and the commands' strains and loads.  Maths and frames: docs/plants.md,
"The Cosserat rod's model".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from harness.plant.cosserat.pyelastica import (
    _batch_cross,
    _batch_matvec,
    _compute_bending_twist_strains,
    _compute_dilatation_rate,
    _compute_shear_stretch_strains,
    _inv_rotate,
    _update_accelerations,
    overload_operator_kinematic_numba,
)


@njit(cache=True)
def rod_loads(pos, vel, Q, omega, J, volume, lengths, tangents, radius, rest_lengths, rest_vor,
              dil, vdil, sigma, kappa, dil_rate, rest_sigma, rest_kappa, shear_matrix, bend_matrix,
              eta_e, eta_v, base_Q, base_B, base_eta, base_kappa0, act_n, act_m, act_m_base,
              node_force, tip_force, analytic_law, objs, cdamp, f_contact, dt, f_int, tau_int, f_ext,
              tau_ext):
    """Loads of one step into f_int (3, nn), tau_int (3, ne), f_ext, tau_ext.  eta_e (3, ne) N s, eta_v
    (3, nv) N m^2 s (implicit): Kelvin-Voigt viscosities; act_n (ne,) N (positive extends), act_m (3, nv),
    act_m_base (3,) N m: active loads; node_force (3, nn) gravity; tip_force (3,); objs, cdamp,
    f_contact: `contact_forces`; analytic_law 1: m = B (kappa - kappa0) / eps, 0: B (kappa - kappa0)."""
    ne = lengths.shape[0]
    nv, nn = ne - 1, ne + 1
    _compute_shear_stretch_strains(pos, volume, lengths, tangents, radius, rest_lengths, rest_vor,
                                   dil, vdil, Q, sigma)
    _compute_bending_twist_strains(Q, rest_vor, kappa)
    _compute_dilatation_rate(pos, vel, lengths, rest_lengths, dil_rate)

    # --- shear/stretch stress n (material frame), Kelvin-Voigt on the strain rate -------------------
    # sigma = Q (x_{i+1} - x_i) / l0 - e3; d sigma / dt = Q dv / l0 - omega x (sigma + e3)
    dv = np.empty((3, ne))
    for i in range(3):
        for k in range(ne):
            dv[i, k] = (vel[i, k + 1] - vel[i, k]) / rest_lengths[k]
    qdv = _batch_matvec(Q, dv)
    se3 = sigma.copy()
    se3[2] += 1.0
    sdot = qdv - _batch_cross(omega, se3)
    n = np.empty((3, ne))
    for i in range(3):
        for k in range(ne):
            n[i, k] = shear_matrix[i, i, k] * (sigma[i, k] - rest_sigma[i, k]) + eta_e[i, k] * sdot[i, k]
    n[2] -= act_n

    # --- bending couples m at the hinges (elastic + active), base half-element hinge -------------------
    m = np.empty((3, nv))
    tension = np.zeros(ne)  # extra chord tension dW/dl from the analytic law (lab, along the chord)
    for k in range(nv):
        w = 0.0
        for i in range(3):
            dk = kappa[i, k] - rest_kappa[i, k]
            el = bend_matrix[i, i, k] * dk
            if analytic_law:
                el /= vdil[k]
                w += el * dk / vdil[k]
            m[i, k] = el - act_m[i, k]
        if analytic_law:
            tension[k] -= 0.25 * w
            tension[k + 1] -= 0.25 * w
    pair = np.empty((3, 3, 2))
    pair[:, :, 0] = base_Q
    pair[:, :, 1] = Q[:, :, 0]
    half0 = 0.5 * rest_lengths[0]
    kb = _inv_rotate(pair)[:, 0] / half0
    mb, wb = np.empty(3), 0.0
    for i in range(3):
        dk = kb[i] - base_kappa0[i]
        el = base_B[i] * dk
        if analytic_law:
            el /= dil[0]
            wb += el * dk / dil[0]
        mb[i] = el - act_m_base[i]
    if analytic_law:
        tension[0] -= 0.25 * wb

    # --- forces: difference of the lab-frame element forces Q^T n + T t ------------------------------
    N = np.empty((3, ne))
    for i in range(3):
        for k in range(ne):
            N[i, k] = (Q[0, i, k] * n[0, k] + Q[1, i, k] * n[1, k] + Q[2, i, k] * n[2, k]
                       + tension[k] * tangents[i, k])
    for i in range(3):
        f_int[i, 0] = N[i, 0]
        for k in range(1, ne):
            f_int[i, k] = N[i, k] - N[i, k - 1]
        f_int[i, ne] = -N[i, ne - 1]

    # --- torques: couple difference + kappa x m (trapezoid) + (sigma + e3) x n l0 + inertial terms ----
    km = _batch_cross(kappa, m)
    kmb = np.cross(kb, mb)
    sn = _batch_cross(se3, n)
    Jw = _batch_matvec(J, omega)
    lag = _batch_cross(Jw, omega)
    for i in range(3):
        for k in range(ne):
            left = mb[i] if k == 0 else m[i, k - 1]
            right = m[i, k] if k < nv else 0.0
            q = 0.0
            if k < nv:
                q += 0.5 * km[i, k] * rest_vor[k]
            if k > 0:
                q += 0.5 * km[i, k - 1] * rest_vor[k - 1]
            else:
                q += 0.5 * kmb[i] * half0
            tau_int[i, k] = (right - left + q + sn[i, k] * rest_lengths[k]
                             + lag[i, k] / dil[k] + Jw[i, k] * dil_rate[k] / (dil[k] * dil[k]))

    # --- external: gravity, tip force; the base node is held (zero net force, zero velocity) ---------
    for i in range(3):
        for k in range(nn):
            f_ext[i, k] = node_force[i, k]
        f_ext[i, nn - 1] += tip_force[i]
    if objs.shape[0] > 0:
        contact_forces(pos, vel, objs, cdamp, f_contact)
        f_ext += f_contact
    for i in range(3):
        for k in range(ne):
            tau_ext[i, k] = 0.0
        f_int[i, 0] = -f_ext[i, 0]

    # --- Kelvin-Voigt bending damping, backward Euler over the kick (tridiagonal per component) -------
    # (J_i / (e_i dt)) (w_i' - w_i) = tau_i - sum_hinges g (w' differences); g = eta / (D0 eps)
    if dt > 0.0:
        g = np.empty(nv)
        a, b, c, r = np.empty(ne), np.empty(ne), np.empty(ne), np.empty(ne)
        for i in range(3):
            for k in range(nv):
                g[k] = eta_v[i, k] / rest_vor[k]
                if analytic_law:
                    g[k] /= vdil[k]
            gb = base_eta[i] / half0
            if analytic_law:
                gb /= dil[0]
            for k in range(ne):
                jh = J[i, i, k] / dil[k] / dt
                diag = jh
                a[k] = 0.0
                c[k] = 0.0
                if k > 0:
                    diag += g[k - 1]
                    a[k] = -g[k - 1]
                else:
                    diag += gb
                if k < nv:
                    diag += g[k]
                    c[k] = -g[k]
                b[k] = diag
                r[k] = jh * omega[i, k] + tau_int[i, k] + tau_ext[i, k]
            # Thomas algorithm
            for k in range(1, ne):
                f = a[k] / b[k - 1]
                b[k] -= f * c[k - 1]
                r[k] -= f * r[k - 1]
            w_new = np.empty(ne)
            w_new[ne - 1] = r[ne - 1] / b[ne - 1]
            for k in range(ne - 2, -1, -1):
                w_new[k] = (r[k] - c[k] * w_new[k + 1]) / b[k]
            for k in range(ne):
                td = 0.0
                if k < nv:
                    td += g[k] * (w_new[k + 1] - w_new[k])
                if k > 0:
                    td -= g[k - 1] * (w_new[k] - w_new[k - 1])
                else:
                    td -= gb * w_new[k]
                tau_int[i, k] += td


@njit(cache=True)
def run_steps(nsteps, dt, pos, vel, Q, omega, acc, alpha, mass, J, invJ, volume, lengths, tangents,
              radius, rest_lengths, rest_vor, dil, vdil, sigma, kappa, dil_rate, rest_sigma, rest_kappa,
              shear_matrix, bend_matrix, eta_e, eta_v, base_Q, base_B, base_eta, base_kappa0, act_n,
              act_m, act_m_base, node_force, tip_force, analytic_law, objs, cdamp, f_contact, f_int, tau_int,
              f_ext, tau_ext):
    """`nsteps` position-Verlet steps of size dt (PyElastica's PositionVerlet order), in place."""
    half = 0.5 * dt
    for _ in range(nsteps):
        overload_operator_kinematic_numba(half, pos, Q, vel, omega)
        rod_loads(pos, vel, Q, omega, J, volume, lengths, tangents, radius, rest_lengths, rest_vor,
                  dil, vdil, sigma, kappa, dil_rate, rest_sigma, rest_kappa, shear_matrix, bend_matrix,
                  eta_e, eta_v, base_Q, base_B, base_eta, base_kappa0, act_n, act_m, act_m_base,
                  node_force, tip_force, analytic_law, objs, cdamp, f_contact, dt, f_int, tau_int, f_ext,
                  tau_ext)
        _update_accelerations(acc, f_int, f_ext, mass, alpha, invJ, tau_int, tau_ext, dil)
        for i in range(3):
            for k in range(vel.shape[1]):
                vel[i, k] += dt * acc[i, k]
            for k in range(omega.shape[1]):
                omega[i, k] += dt * alpha[i, k]
        overload_operator_kinematic_numba(half, pos, Q, vel, omega)


@njit(cache=True)
def contact_forces(pos, vel, objs, cdamp, f_contact):
    """Frictionless penalty contact ON the rod's nodes j >= 1, into f_contact (3, nn) (N, world frame):
    objs (no, 6) rows [kind (0 plane, 1 sphere), X, Z, nX, nZ, r (plane) or R + r (sphere)], cdamp
    (no, nn + 1) rows [k N/m, c_j N s/m]; penetration g > 0 gives (k g - c n . v_j) n (Gazzola et al.
    2018, eq. 4.8; docs/plants.md, "Contact on the rod")."""
    nn = pos.shape[1]
    f_contact[:] = 0.0
    for o in range(objs.shape[0]):
        k = cdamp[o, 0]
        for j in range(1, nn):
            dx = pos[0, j] - objs[o, 1]
            dz = pos[2, j] - objs[o, 2]
            if objs[o, 0] == 0.0:
                nx, nz = objs[o, 3], objs[o, 4]
                g = objs[o, 5] - (nx * dx + nz * dz)
            else:
                dist = np.sqrt(dx * dx + dz * dz)
                g = objs[o, 5] - dist
                if g <= 0.0 or dist == 0.0:
                    continue
                nx, nz = dx / dist, dz / dist
            if g <= 0.0:
                continue
            f = k * g - cdamp[o, j + 1] * (nx * vel[0, j] + nz * vel[2, j])
            f_contact[0, j] += f * nx
            f_contact[2, j] += f * nz


# --- constant-curvature geometry and its least-squares fit ------------------------------------------------


@njit(cache=True)
def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def _midpoints(arc, smid):
    """smid (m,) <- arc length at the middle of each element of arcs arc (m,); returns (total length,
    mean of smid, sum of squared deviations of smid)."""
    m = arc.shape[0]
    acc = 0.0
    for t in range(m):
        smid[t] = acc + 0.5 * arc[t]
        acc += arc[t]
    sbar = 0.0
    for t in range(m):
        sbar += smid[t]
    sbar /= m
    sxx = 0.0
    for t in range(m):
        sxx += (smid[t] - sbar) ** 2
    return acc, sbar, sxx


@njit(cache=True)
def cc_fit(xz, vxz, bounds, n_iter, q2, dq2):
    """Least-squares CC fit (docs/plants.md, Sensing) of the nodes xz, rates vxz (nn, 2) [X, Z] of each
    section (boundary nodes bounds (4,)) into q2 = [d, k], dq2 (first-order rates)."""
    nn = xz.shape[0]
    ne = nn - 1
    phi, phid, c, cd = np.empty(ne), np.empty(ne), np.empty(ne), np.empty(ne)
    prev = 0.0
    for j in range(ne):
        ex = xz[j + 1, 0] - xz[j, 0]
        ez = xz[j + 1, 1] - xz[j, 1]
        vx = vxz[j + 1, 0] - vxz[j, 0]
        vz = vxz[j + 1, 1] - vxz[j, 1]
        c2 = ex * ex + ez * ez
        c[j] = np.sqrt(c2)
        cd[j] = (ex * vx + ez * vz) / c[j]
        a = np.arctan2(ex, ez)
        # unwrap against the previous chord (|turn| < pi per element)
        a = prev + _wrap(a - prev) if j > 0 else _wrap(a)
        phi[j] = a
        prev = a
        phid[j] = (ez * vx - ex * vz) / c2
    for s in range(3):
        j0 = bounds[s]
        j1 = bounds[s + 1]
        m = j1 - j0
        arc, smid, w = np.empty(m), np.empty(m), np.empty(m)
        for t in range(m):
            arc[t] = c[j0 + t]
        k = 0.0
        for _ in range(n_iter):
            _, sbar, sxx = _midpoints(arc, smid)
            pbar = 0.0
            for t in range(m):
                pbar += phi[j0 + t]
            pbar /= m
            sxy = 0.0
            for t in range(m):
                sxy += (smid[t] - sbar) * (phi[j0 + t] - pbar)
            k = sxy / sxx if m > 1 else 0.0
            # chord -> arc length for the fitted curvature: a = c / sinc(k a / 2), solved as 2 asin(kc/2)/k
            for t in range(m):
                u = 0.5 * k * c[j0 + t]
                if abs(u) < 1e-6:
                    arc[t] = c[j0 + t] * (1.0 + u * u / 6.0)
                elif abs(u) < 1.0:
                    arc[t] = c[j0 + t] * np.arcsin(u) / u
                else:
                    arc[t] = c[j0 + t] * 0.5 * np.pi / min(abs(u), 1.0)
        d, sbar, sxx = _midpoints(arc, smid)
        for t in range(m):
            w[t] = (smid[t] - sbar) / sxx if m > 1 else 0.0
        # rates: a' = (da/dc) c' + (da/dk) k', k' = sum w (phi' - k s') (exact on CC data), iterated
        dk, dd = 0.0, 0.0
        for _ in range(3):
            dd = 0.0
            dk_new = 0.0
            sd = 0.0
            for t in range(m):
                cj = c[j0 + t]
                u = 0.5 * k * cj
                if abs(u) < 1e-4:
                    ad = cd[j0 + t] * (1.0 + 0.5 * u * u) + dk * cj * cj * cj * k / 12.0
                else:
                    r = 1.0 / np.sqrt(max(1.0 - u * u, 1e-12))
                    ad = cd[j0 + t] * r + dk * (cj * r - arc[t]) / k
                sdm = sd + 0.5 * ad
                sd += ad
                dk_new += w[t] * (phid[j0 + t] - k * sdm)
                dd += ad
            dk = dk_new
        q2[s] = d
        q2[3 + s] = k
        dq2[s] = dd
        dq2[3 + s] = dk


@njit(cache=True)
def fit_rod(pos, vel, xz, vxz, bounds, n_iter, q2, dq2):
    """`cc_fit` of the rod's nodes pos, vel (3, nn) (the plane's X, Z rows copied into the scratch xz, vxz
    (nn, 2)) into q2, dq2 (6,)."""
    xz[:, 0], xz[:, 1] = pos[0], pos[2]
    vxz[:, 0], vxz[:, 1] = vel[0], vel[2]
    cc_fit(xz, vxz, bounds, n_iter, q2, dq2)


# --- commands: rest strains (servo) and active loads (feed-forward / torque) ------------------------------


@njit(cache=True)
def _at_hinges(v, sec, l0, out, base):
    """A per-section value v (3,) as a couple about the binormal at the rod's hinges: out (3, ne - 1) <-
    [0, rest-length l0 (ne,) weighted mean of v over the two elements of each hinge, 0], base (3,) <-
    [0, v[0], 0].  sec (ne,): section of each element."""
    out[:] = 0.0
    out[1] = (l0[:-1] * v[sec[:-1]] + l0[1:] * v[sec[1:]]) / (l0[:-1] + l0[1:])
    base[:] = 0.0
    base[1] = v[0]


@njit(cache=True)
def rest_strains(q2c, n, L0, sec, l0, rest_sigma, rest_kappa, base_kappa0):
    """Servo command q2c (6,) = [d, k] -> rest_sigma (3, ne) <- [0, 0, (d / L0) sinc(k d / 2n) - 1],
    rest_kappa (3, nv) <- [0, k d / L0 (`_at_hinges`), 0], base_kappa0 (3,) <- [0, k_1 d_1 / L0_1, 0]."""
    sig, kap = np.empty(3), np.empty(3)
    for i in range(3):
        d = q2c[i]
        k = q2c[3 + i]
        h = d / n
        x = 0.5 * k * h
        s = 1.0 - x * x / 6.0 if abs(x) < 1e-8 else np.sin(x) / x
        sig[i] = d / L0[i] * s - 1.0
        kap[i] = k * d / L0[i]
    rest_sigma[:2] = 0.0
    rest_sigma[2] = sig[sec]
    _at_hinges(kap, sec, l0, rest_kappa, base_kappa0)


@njit(cache=True)
def active_loads(T2, q2, sec, l0, act_n, act_m, act_m_base):
    """Generalized forces T2 (6,) [T_d N, T_k N m] at the fitted q2 (6,) -> the internal active loads
    (see `harness.plant.cosserat.rod`, Actuation): mu = T_k / d, act_n (ne,) <- T_d - k mu per element,
    act_m (3, nv) <- [0, mu (rest-length weighted mean at the hinges), 0], act_m_base (3,) <- [0, mu_1, 0]."""
    mu, ax = np.empty(3), np.empty(3)
    for i in range(3):
        mu[i] = T2[3 + i] / q2[i]
        ax[i] = T2[i] - q2[3 + i] * mu[i]
    _section_loads(mu, ax, sec, l0, act_n, act_m, act_m_base)


@njit(cache=True)
def muscle_loads(p, radius, sec, l0, act_n, act_m, act_m_base):
    """Muscle group forces p (6,) [p+_1, p-_1, ...] (N, pushing, at s = +r_i, -r_i; radius (3,) m) -> the
    active loads of their fibres by virtual work per unit length (a fibre l_s = int (1 - s kappa) ds):
    axial force p+ + p- and couple mu = -r (p+ - p-) on every cross-section of the section."""
    mu, ax = np.empty(3), np.empty(3)
    for i in range(3):
        mu[i] = -radius[i] * (p[2 * i] - p[2 * i + 1])
        ax[i] = p[2 * i] + p[2 * i + 1]
    _section_loads(mu, ax, sec, l0, act_n, act_m, act_m_base)


@njit(cache=True)
def _section_loads(mu, ax, sec, l0, act_n, act_m, act_m_base):
    """Per-section couple mu (3,) N m and axial force ax (3,) N -> act_n (ne,), act_m (3, nv), act_m_base."""
    act_n[:] = ax[sec]
    _at_hinges(mu, sec, l0, act_m, act_m_base)
