"""Per-step loop kernels (numba-compatible; compiled by `harness.loop.fast` together with controllers/).

Everything that happens once per control step and is not MuJoCo's `mj_step` lives here, fused, so
that the Python side of the loop is one kernel call plus `mj_step`:
  sensing noise -> master law -> slave law -> record row (and, for the analytic plant, RK4).

Status codes returned by the kernels: `controllers.status` (ST_* here; a MuJoCo warning is counted by
MuJoCo in mjData.warning and checked after every mj_step, so the run stops at the step that raised it).
"""

from __future__ import annotations

import numpy as np

from controllers.control import (
    MASTER_INFO,
    MI_DE1,
    MI_E1,
    MI_X1,
    SI_BM,
    SI_DE2,
    SI_E2,
    SI_X2,
    SI_YA,
    SLAVE_INFO,
    control_laws,
)
from controllers.master import master_kernel
from controllers.scratch import scratch, scratch_zeros
from controllers.status import (
    ST_NONFINITE,
    ST_OK,
    ST_RUNAWAY,
    ST_SECTION_LENGTH,
)
from controllers.subtasks import limits_kernel
from controllers.tip import tip_kinematics
from harness.plant.analytic import plant_accel

# record row layout (must match harness.loop.trajectory.ROW_FIELDS)
R_T, R_Q1, R_DQ1, R_Q2, R_DQ2, R_XD, R_X1, R_X2 = 0, 1, 3, 5, 11, 17, 19, 21
R_E1, R_E2, R_DE1, R_DE2, R_BETA, R_YA, R_DEN, R_T1, R_T2, R_U2 = 23, 25, 27, 29, 31, 32, 33, 39, 41, 47
ROW_W = 53
RUNAWAY = 1.0  # m: |e1| or |e2| beyond this is a runaway (the workspace is ~1 m)


# --- the per-step glue every loop body shares (the compiled loops and the Python-stepped loop) ---------
DQ2_FILTER = 7  # noise-table columns of the sensed-dq2 filter: gain, filtered dq2 (6)


def runaway(row):
    """True when the record row's |e1| or |e2| (1-norm, m) exceeds RUNAWAY."""
    return (abs(row[R_E1]) + abs(row[R_E1 + 1]) > RUNAWAY) or (abs(row[R_E2]) + abs(row[R_E2 + 1]) > RUNAWAY)


def section_collapsed(state):
    """True when a section length q2[0:3] = state[4:7] (m) is <= 0."""
    return state[4] <= 0.0 or state[5] <= 0.0 or state[6] <= 0.0


def servo_reference_step(ref, u2, dt):
    """The servo reference ref (12,) = [q2_ref, dq2_ref] after one control step dt (s) with the slave
    input u2 (6,) (eq. 18): semi-implicit Euler, dq2_ref += u2 dt, then q2_ref += dq2_ref dt."""
    for a in range(6):
        ref[6 + a] += u2[a] * dt
        ref[a] += ref[6 + a] * dt


def add_noise(state, noise_row, scale, out):
    """AWGN at a given SNR on each fed-back vector (q1, dq1, q2, dq2 = state[0:2], [2:4], [4:10],
    [10:16]): std = rms(vector) * scale, scale = 10^(-SNR/20) (signal power measured per step;
    ``noise_model = "per_vector"``, the model before per-channel SNR: mixed units, so e.g. the curvature
    noise scales with the section lengths, and a vector at rest gets no noise)."""
    bounds = (0, 2, 4, 10, 16)
    for v in range(4):
        a = bounds[v]
        b = bounds[v + 1]
        p = 0.0
        for i in range(a, b):
            p += state[i] * state[i]
        std = np.sqrt(p / (b - a)) * scale
        for i in range(a, b):
            out[i] = state[i] + std * noise_row[i]


def add_noise_channel(state, noise, k, scale, out):
    """AWGN at a given SNR on each fed-back signal separately (``noise_model = "per_channel"``, the
    default): std_i = sqrt(P_i) * scale with P_i the running mean square of the TRUE signal i over the
    control steps 0..k (a causal estimate of the channel's power over the run, the power MATLAB's
    ``awgn(x, SNR, 'measured')`` would measure on that channel's whole time series).
    noise (n, 32): [:, 0:16] standard normals, noise[0, 16:32] the running sums of squares (updated
    here, so the table must be fresh for each run and steps visited in order k = 0, 1, ...)."""
    for i in range(16):
        noise[0, 16 + i] += state[i] * state[i]
        std = np.sqrt(noise[0, 16 + i] / (k + 1)) * scale
        out[i] = state[i] + std * noise[k, i]


def record_row(t, state, xd, dxd, mpk, gains, spec, T1, T2, u2, deN, row):
    """Fill one record row from the noise-free state (16,) and the commands."""
    row[R_T] = t
    for i in range(16):
        row[R_Q1 + i] = state[i]
    x1 = scratch(2)
    J1 = scratch((2, 2))
    Jd1 = scratch((2, 2))
    M1 = scratch((2, 2))
    N1 = scratch(2)
    master_kernel(mpk, state[0:2], state[2:4], x1, J1, Jd1, M1, N1)
    x2 = scratch(2)
    J2 = scratch((2, 6))
    H = scratch((2, 6, 6))
    q2 = state[4:10]
    dq2 = state[10:16]
    tip_kinematics(q2, dq2, 1, x2, J2, H, H)
    for i in range(2):
        dx1 = J1[i, 0] * state[2] + J1[i, 1] * state[3]
        dx2 = 0.0
        for a in range(6):
            dx2 += J2[i, a] * dq2[a]
        row[R_XD + i] = xd[i]
        row[R_X1 + i] = x1[i]
        row[R_X2 + i] = x2[i]
        row[R_E1 + i] = xd[i] - x1[i]
        row[R_E2 + i] = x1[i] - x2[i]
        row[R_DE1 + i] = dxd[i] - dx1
        row[R_DE2 + i] = dx1 - dx2
        row[R_T1 + i] = T1[i]
    A00 = 0.0
    A01 = 0.0
    A11 = 0.0
    for a in range(6):
        A00 += J2[0, a] * J2[0, a]
        A01 += J2[0, a] * J2[1, a]
        A11 += J2[1, a] * J2[1, a]
    det = A00 * A11 - A01 * A01
    bm = np.sqrt(det) if det > 0.0 else 0.0
    beta = spec[0] * bm
    if spec[1] != 0.0:
        g = scratch(6)
        gd = scratch(6)
        beta += spec[1] * limits_kernel(spec, q2, scratch_zeros(6), g, gd)
    row[R_BETA] = bm
    row[R_YA] = np.exp(-gains[4] * beta)
    for a in range(6):
        row[R_DEN + a] = deN[a]
        row[R_T2 + a] = T2[a]
        row[R_U2 + a] = u2[a]


def record_row_info(t, state, xd, dxd, minfo, sinfo, T1, T2, u2, deN, row):
    """record_row when both laws ran on the noise-free state with status 0: x1, e1, de1 from the
    master info, x2, e2, de2, beta_m, y_a from the slave info (the same operations on the same
    numbers as record_row: identical rows, without a second master_kernel / tip_kinematics)."""
    row[R_T] = t
    for i in range(16):
        row[R_Q1 + i] = state[i]
    for i in range(2):
        row[R_XD + i] = xd[i]
        row[R_X1 + i] = minfo[MI_X1 + i]
        row[R_X2 + i] = sinfo[SI_X2 + i]
        row[R_E1 + i] = minfo[MI_E1 + i]
        row[R_E2 + i] = sinfo[SI_E2 + i]
        row[R_DE1 + i] = minfo[MI_DE1 + i]
        row[R_DE2 + i] = sinfo[SI_DE2 + i]
        row[R_T1 + i] = T1[i]
    row[R_BETA] = sinfo[SI_BM]
    row[R_YA] = sinfo[SI_YA]
    for a in range(6):
        row[R_DEN + a] = deN[a]
        row[R_T2 + a] = T2[a]
        row[R_U2 + a] = u2[a]


def sense_state(state, noise, k, noise_scale, sensed):
    """The sensed state (16,) at control step k: the true state plus AWGN of either noise model
    (noise (n, 32) per channel, `add_noise_channel`; (n, 16) per vector, `add_noise`), or the true
    state itself when noise_scale == 0 (normals not read).  With DQ2_FILTER more columns (row 0: gain
    alpha, filtered dq2 y; `common.noise_table`): sensed dq2 <- y += alpha (sensed dq2 - y), y = the
    sensed dq2 at k = 0."""
    if noise_scale > 0.0 and noise.shape[1] >= 32:
        add_noise_channel(state, noise, k, noise_scale, sensed)
    elif noise_scale > 0.0:
        add_noise(state, noise[k], noise_scale, sensed)
    else:
        for i in range(16):
            sensed[i] = state[i]
    if noise.shape[1] % 16 == DQ2_FILTER:
        f = noise.shape[1] - DQ2_FILTER
        for i in range(6):
            if k > 0:
                noise[0, f + 1 + i] += noise[0, f] * (sensed[10 + i] - noise[0, f + 1 + i])
            else:
                noise[0, f + 1 + i] = sensed[10 + i]
            sensed[10 + i] = noise[0, f + 1 + i]


def control_step(t, state, traj, noise, k, noise_scale, mpk_c, spk_c, nodes, weights, gains, spec, F,
                 xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, row):
    """One control step at time t on the true state (16,): x_d(t) into xd, dxd, ddxd; the sensed
    state (true state + AWGN noise_scale * noise[k], noise (n, 16) read only if noise_scale > 0) into
    sensed; both laws (control_laws); the record row of the true state into row.  Returns
    control_laws' status."""
    desired(traj, t, xd, dxd, ddxd)
    sense_state(state, noise, k, noise_scale, sensed)
    st = control_laws(mpk_c, spk_c, nodes, weights, gains, spec, sensed, xd, dxd, ddxd, F,
                      T1, T2, u2, deN, minfo, sinfo)
    if noise_scale == 0.0 and st == 0:  # laws ran on the true state: reuse their kinematics
        record_row_info(t, state, xd, dxd, minfo, sinfo, T1, T2, u2, deN, row)
    else:
        record_row(t, state, xd, dxd, mpk_c, gains, spec, T1, T2, u2, deN, row)
    return st


def desired(traj, t, xd, dxd, ddxd):
    """x_d(t), eq. (40) generalised: traj = [cx, cz, ax, az, w]."""
    w = traj[4]
    s = np.sin(w * t)
    c = np.cos(w * t)
    xd[0] = traj[0] + traj[2] * s
    xd[1] = traj[1] + traj[3] * c
    dxd[0] = traj[2] * w * c
    dxd[1] = -traj[3] * w * s
    ddxd[0] = -traj[2] * w * w * s
    ddxd[1] = -traj[3] * w * w * c


def plant_substeps(state, t, h, nsub, continuous, model, F, mpk_p, spk_p, T1, T2, u2, deN, minfo, sinfo, xd,
                   dxd, ddxd, k1s, k2s, k3s, k4s, tmp):
    """nsub RK4 steps of h (s) of the analytic plant (`harness.plant.analytic.plant_accel`: its packed
    params mpk_p, spk_p, the forces model.F it feels (1)) from time t, in place on state (16,).  The
    commands T1 (2,), T2 (6,) are held over the steps (zero-order hold) unless `continuous`: then both
    laws (model's nominal params, F (4,) the forces they get) are evaluated on every RK4 stage's state (no
    noise), writing T1, T2, u2, deN, minfo, sinfo, xd, dxd, ddxd.  k1s..k4s, tmp (16,): work.
    Returns ST_OK, ST_NONFINITE or a law's status."""
    mpk_c, spk_c, nodes, weights, gains, spec, Fp, traj, _s0 = model
    for j in range(nsub):
        ts = t + j * h
        # RK4 stage 1
        if continuous:
            desired(traj, ts, xd, dxd, ddxd)
            st = control_laws(mpk_c, spk_c, nodes, weights, gains, spec, state, xd, dxd, ddxd, F,
                              T1, T2, u2, deN, minfo, sinfo)
            if st != 0:
                return st
        if not plant_accel(mpk_p, spk_p, nodes, weights, state, T1, T2, Fp, k1s):
            return ST_NONFINITE
        for i in range(16):
            tmp[i] = state[i] + 0.5 * h * k1s[i]
        if continuous:
            desired(traj, ts + 0.5 * h, xd, dxd, ddxd)
            control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                         T1, T2, u2, deN, minfo, sinfo)
        if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, Fp, k2s):
            return ST_NONFINITE
        for i in range(16):
            tmp[i] = state[i] + 0.5 * h * k2s[i]
        if continuous:
            control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                         T1, T2, u2, deN, minfo, sinfo)
        if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, Fp, k3s):
            return ST_NONFINITE
        for i in range(16):
            tmp[i] = state[i] + h * k3s[i]
        if continuous:
            desired(traj, ts + h, xd, dxd, ddxd)
            control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                         T1, T2, u2, deN, minfo, sinfo)
        if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, Fp, k4s):
            return ST_NONFINITE
        for i in range(16):
            state[i] += h / 6.0 * (k1s[i] + 2.0 * k2s[i] + 2.0 * k3s[i] + k4s[i])
    return ST_OK


def analytic_chunk(k0, k1, model, plant, data):
    """Run control steps k0..k1-1 of the closed loop on the analytic plant, in place on the state.

    model: the run's `harness.loop.common.RunModel` (the controller's nominal packed params mpk_c, spk_c,
    quadrature, gains, sub-task, Fp (4,) the interaction forces the plant feels (1), desired trajectory);
    plant: (dt control period (s), nsub, continuous, mpk_p, spk_p: the plant's own packed params);
    data: (state (16,), noise, noise_scale, F (4,) = [F1, F2] the laws get (13), (17), rows of this chunk,
    cmdbuf (delay + 1, 8): the ring of [T1, T2] commands, delay: the actuation delay in control steps).
    Zero-order hold of the commands over the control step (nsub RK4 steps of dt/nsub) unless
    `continuous`, where both laws are evaluated in every RK4 stage on the true state (no noise; delay 0).
    With a delay the plant gets the commands of step k - delay (of step 0 while k < delay), as on the
    MuJoCo plant.  Returns (status, number of completed steps)."""
    mpk_c, spk_c, nodes, weights, gains, spec, Fp, traj, _s0 = model
    dt, nsub, continuous, mpk_p, spk_p = plant
    state, noise, noise_scale, F, rows, cmdbuf, delay = data
    nb = delay + 1
    T1h = scratch_zeros(2)
    T2h = scratch_zeros(6)
    # the control step's arrays: made here, not by a shared helper (a scratch array lives in the frame that
    # makes it: a helper would hand back arrays over its finished frame)
    T1 = scratch_zeros(2)
    T2 = scratch_zeros(6)
    u2 = scratch_zeros(6)
    deN = scratch_zeros(6)
    minfo = scratch(MASTER_INFO)
    sinfo = scratch(SLAVE_INFO)
    sensed = scratch(16)
    xd = scratch(2)
    dxd = scratch(2)
    ddxd = scratch(2)
    k1s = scratch(16)
    k2s = scratch(16)
    k3s = scratch(16)
    k4s = scratch(16)
    tmp = scratch(16)
    h = dt / nsub
    for k in range(k0, k1):
        t = k * dt
        st = control_step(t, state, traj, noise, k, noise_scale, mpk_c, spk_c, nodes, weights, gains, spec, F,
                          xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, rows[k - k0])
        if st != 0:
            return st, k - k0 + 1
        slot = cmdbuf[k % nb]  # the plant gets the commands of step k - delay (the ring cmdbuf)
        for i in range(2):
            slot[i] = T1[i]
        for i in range(6):
            slot[2 + i] = T2[i]
        use = cmdbuf[(k - delay) % nb] if k >= delay else cmdbuf[0]
        for i in range(2):
            T1h[i] = use[i]
        for i in range(6):
            T2h[i] = use[2 + i]
        st = plant_substeps(state, t, h, nsub, continuous, model, F, mpk_p, spk_p, T1h, T2h, u2, deN, minfo,
                            sinfo, xd, dxd, ddxd, k1s, k2s, k3s, k4s, tmp)
        if st != ST_OK:
            return st, k - k0 + 1
        for i in range(16):
            if not np.isfinite(state[i]):
                return ST_NONFINITE, k - k0 + 1
        if section_collapsed(state):
            return ST_SECTION_LENGTH, k - k0 + 1
        if runaway(rows[k - k0]):
            return ST_RUNAWAY, k - k0 + 1
    return ST_OK, k1 - k0


KERNELS = ("runaway", "section_collapsed", "servo_reference_step", "plant_substeps", "add_noise",
           "add_noise_channel", "sense_state", "record_row", "record_row_info", "control_step", "desired",
           "analytic_chunk")
