"""Per-step loop kernels (numba-compatible): sensing, the record row, the checks, the loop body
`loop_chunk`, the analytic plant's RK4 and the Python-stepped loop's glue.  Statuses: `controllers.status`."""

from __future__ import annotations

import math
import types

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
from controllers.status import ST_NONFINITE, ST_OK, ST_PLANT_STATE, ST_RUNAWAY, ST_SECTION_LENGTH
from controllers.subtasks import limits_kernel
from controllers.tip import tip_kinematics
from harness.loop.force_kernels import CONTACT_INFO
from harness.loop.trajectory import ROW_SLICES
from harness.plant.analytic import plant_accel

# the record row's columns, in the order of `trajectory.ROW_FIELDS`
(R_T, R_Q1, R_DQ1, R_Q2, R_DQ2, R_XD, R_X1, R_X2, R_E1, R_E2, R_DE1, R_DE2, R_BETA, R_YA, R_DEN, R_T1, R_T2,
 R_U2, R_FT, R_FS, R_CI, R_HAND) = (s.start for s in ROW_SLICES.values())
RUNAWAY = 1.0  # m: |e1| or |e2| beyond this is a runaway (the workspace is ~1 m)
EXPLODING = 1e6  # a diverged plant state: stepped |state| (status 8), MuJoCo loop any entry (6)
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


def ring_index(k, delay):
    """The slot of the actuation-delay ring (delay + 1 slots) whose commands the plant gets at step k:
    those of step k - delay, of step 0 while k < delay."""
    return (k - delay) % (delay + 1) if k >= delay else 0


def add_noise(state, noise_row, scale, out):
    """AWGN on each fed-back vector (q1, dq1, q2, dq2; ``noise_model = "per_vector"``): std = rms(vector)
    * scale, scale = 10^(-SNR/20), the power measured per step (a vector at rest gets no noise)."""
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
    """AWGN on each fed-back signal (``noise_model = "per_channel"``): std_i = sqrt(P_i) * scale, P_i the
    running mean square of the true signal i over steps 0..k.  noise (n, 32): [:, 0:16] standard normals,
    noise[0, 16:32] the running sums of squares (updated here: a fresh table per run, steps in order)."""
    for i in range(16):
        noise[0, 16 + i] += state[i] * state[i]
        std = np.sqrt(noise[0, 16 + i] / (k + 1)) * scale
        out[i] = state[i] + std * noise[k, i]


def record_row(t, state, model, law, row, info):
    """Fill one record row from the noise-free state (16,), `model` (a `RunModel`) and law (`loop_chunk`).
    info: both laws ran on this state with status 0: the kinematics from their minfo / sinfo (the same
    row without a second master_kernel / tip_kinematics)."""
    T1, T2, u2, deN, minfo, sinfo, xd, dxd, _dd, _s = law
    row[R_T] = t
    for i in range(16):
        row[R_Q1 + i] = state[i]
    for i in range(2):
        row[R_XD + i] = xd[i]
        row[R_T1 + i] = T1[i]
    for a in range(6):
        row[R_DEN + a] = deN[a]
        row[R_T2 + a] = T2[a]
        row[R_U2 + a] = u2[a]
    if info:
        for i in range(2):
            row[R_X1 + i] = minfo[MI_X1 + i]
            row[R_X2 + i] = sinfo[SI_X2 + i]
            row[R_E1 + i] = minfo[MI_E1 + i]
            row[R_E2 + i] = sinfo[SI_E2 + i]
            row[R_DE1 + i] = minfo[MI_DE1 + i]
            row[R_DE2 + i] = sinfo[SI_DE2 + i]
        row[R_BETA] = sinfo[SI_BM]
        row[R_YA] = sinfo[SI_YA]
        return
    x1 = scratch(2)
    J1 = scratch((2, 2))
    Jd1 = scratch((2, 2))
    M1 = scratch((2, 2))
    N1 = scratch(2)
    master_kernel(model.mpk_c, state[0:2], state[2:4], x1, J1, Jd1, M1, N1)
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
        row[R_X1 + i] = x1[i]
        row[R_X2 + i] = x2[i]
        row[R_E1 + i] = xd[i] - x1[i]
        row[R_E2 + i] = x1[i] - x2[i]
        row[R_DE1 + i] = dxd[i] - dx1
        row[R_DE2 + i] = dx1 - dx2
    A00 = 0.0
    A01 = 0.0
    A11 = 0.0
    for a in range(6):
        A00 += J2[0, a] * J2[0, a]
        A01 += J2[0, a] * J2[1, a]
        A11 += J2[1, a] * J2[1, a]
    det = A00 * A11 - A01 * A01
    bm = np.sqrt(det) if det > 0.0 else 0.0
    spec = model.spec
    beta = spec[0] * bm
    if spec[1] != 0.0:
        g = scratch(6)
        gd = scratch(6)
        beta += spec[1] * limits_kernel(spec, q2, scratch_zeros(6), g, gd)
    row[R_BETA] = bm
    row[R_YA] = np.exp(-model.gains[4] * beta)


def sense_state(state, noise, k, noise_scale, sensed):
    """The sensed state (16,) at step k: the true state plus AWGN (noise (n, 32): `add_noise_channel`;
    (n, 16): `add_noise`; none when noise_scale == 0).  With DQ2_FILTER more columns (row 0: gain alpha,
    filtered dq2 y): sensed dq2 <- y += alpha (sensed dq2 - y), y = the sensed dq2 at k = 0.  Returns
    whether the sensed state is the true state (no noise, no filter)."""
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
        return False
    return noise_scale == 0.0


def control_step(k, t, model, state, noise, noise_scale, F, law, row):
    """Control step k at time t on the true state (16,): x_d(t), the sensed state, both laws
    (`control_laws`, forces F (4,) N) into law (`loop_chunk`), the record row of the true state.  Returns
    control_laws' status."""
    T1, T2, u2, deN, minfo, sinfo, xd, dxd, ddxd, sensed = law
    m = model
    desired(m.traj, t, xd, dxd, ddxd)
    exact = sense_state(state, noise, k, noise_scale, sensed)
    st = control_laws(m.mpk_c, m.spk_c, m.nodes, m.weights, m.gains, m.spec, sensed, xd, dxd, ddxd, F,
                      T1, T2, u2, deN, minfo, sinfo)
    record_row(t, state, model, law, row, exact and st == 0)  # laws on the true state
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


RK4_T = (0.0, 0.5, 0.5, 1.0)  # the classical RK4's stage times (fractions of the step)


def plant_sense(k, state, row, plant):
    """Bound per plant: the true state (16,) of step k and the row's interaction columns; a status."""
    raise NotImplementedError


def plant_command(slot, law, plant):
    """Bound per plant: the step's commands into its ring slot."""
    raise NotImplementedError


def plant_advance(k, st, use, state, law, plant):
    """Bound per plant: the step with the ring slot `use` of step k - delay (not when st != 0); a status."""
    raise NotImplementedError


def loop_chunk(k0, k1, model, data, plant):
    """Control steps k0..k1-1 of a compiled loop: `plant_sense` -> `control_step` -> status 4 on a runaway
    row -> `plant_command` into the ring slot of step k -> `plant_advance` with the slot of step k - delay.
    The plant kernels are bound per plant (`bind`); plant: their constants and buffers.  data: (state (16,),
    noise, noise_scale, rows (n, ROW_WIDTH), cmdbuf (delay + 1, w), delay, dt (s)).  Returns (status,
    completed steps)."""
    state, noise, noise_scale, rows, cmdbuf, delay, dt = data
    # the step's arrays are made here, not by a helper: a scratch array lives in the frame that makes it
    law = (scratch_zeros(2), scratch_zeros(6), scratch_zeros(6), scratch_zeros(6), scratch(MASTER_INFO),
           scratch(SLAVE_INFO), scratch(2), scratch(2), scratch(2), scratch(16))
    for k in range(k0, k1):
        r = rows[k]
        st = plant_sense(k, state, r, plant)
        if st != ST_OK:
            return st, k - k0
        st = control_step(k, k * dt, model, state, noise, noise_scale, r[R_FS:R_FS + 4], law, r)
        if st == 0 and runaway(r):
            st = ST_RUNAWAY
        if st == 0:
            plant_command(cmdbuf[k % (delay + 1)], law, plant)
        st = plant_advance(k, st, cmdbuf[ring_index(k, delay)], state, law, plant)
        if st != ST_OK:
            return st, k + 1 - k0
    return ST_OK, k1 - k0


def bind(fn, name, **kernels):
    """`fn` with the global names `kernels` bound to those kernels, as the kernel `name` (a loop body of one
    plant; `harness.loop.fast` compiles it with the compiled kernels bound)."""
    out = types.FunctionType(fn.__code__, {**fn.__globals__, **kernels}, name)
    out.__qualname__ = name
    out.bound = kernels
    return out


def analytic_sense(k, state, row, plant):
    """The analytic plant's state is the loop's; its force columns are constant (set by the driver)."""
    return ST_OK


def analytic_command(slot, law, plant):
    """slot (8,) <- [T1, T2]."""
    T1, T2 = law[0], law[1]
    for i in range(2):
        slot[i] = T1[i]
    for i in range(6):
        slot[2 + i] = T2[i]


def analytic_advance(k, st, use, state, law, plant):
    """nsub classical RK4 steps h = dt / nsub of the analytic plant (`plant_accel`, its packed params
    mpk_p, spk_p, the forces model.F (1)) with the commands use = [T1, T2] held, or, `continuous`, both laws
    (F (4,) the forces they get) on every stage's state without noise.  plant: (model, F, dt (s), nsub,
    continuous, mpk_p, spk_p, ks (4, 16), tmp (16,) work).  Status: the laws', 1 on a non-finite state, 5
    on a section length <= 0."""
    if st != 0:
        return st
    m, F, dt, nsub, continuous, mpk_p, spk_p, ks, tmp = plant
    _T1, _T2, u2, deN, minfo, sinfo, xd, dxd, ddxd, _s = law
    T1 = use[0:2]
    T2 = use[2:8]
    t = k * dt
    h = dt / nsub
    for j in range(nsub):
        ts = t + j * h
        for s in range(4):
            x = state if s == 0 else tmp
            if continuous:
                desired(m.traj, ts + RK4_T[s] * h, xd, dxd, ddxd)
                st = control_laws(m.mpk_c, m.spk_c, m.nodes, m.weights, m.gains, m.spec, x, xd, dxd, ddxd, F,
                                  T1, T2, u2, deN, minfo, sinfo)
                if s == 0 and st != 0:
                    return st
            if not plant_accel(mpk_p, spk_p, m.nodes, m.weights, x, T1, T2, m.F, ks[s]):
                return ST_NONFINITE
            if s < 3:
                c = RK4_T[s + 1]
                for a in range(16):
                    tmp[a] = state[a] + c * h * ks[s, a]
        for a in range(16):
            state[a] += h / 6.0 * (ks[0, a] + 2.0 * ks[1, a] + 2.0 * ks[2, a] + ks[3, a])
    for a in range(16):
        if not np.isfinite(state[a]):
            return ST_NONFINITE
    return ST_SECTION_LENGTH if section_collapsed(state) else ST_OK


# the analytic plant's loop (`analytic_loop`); plant: `analytic_advance`'s
analytic_chunk = bind(loop_chunk, "analytic_chunk", plant_sense=analytic_sense,
                      plant_command=analytic_command, plant_advance=analytic_advance)


# --- the Python-stepped loop's glue (`harness.loop.stepped_loop.Stepper`) ----------------------------
# loop: (state (16,), noise, noise_scale, F_true (4,) N, F the controller gets (4,), contact (5,), forces
# ignored, servo reference ref (12,), dt (s), servo)
def stepped_state_check(loop):
    """Status of the true state: 8 if non-finite or |state| > EXPLODING, 5 if a section length <= 0, else
    0; then the controller's F <- 0 if ignored else F_true."""
    state, _n, _s, Ftrue, Fctl, _c, ignored, _r, _dt, _servo = loop
    total = 0.0
    for i in range(state.shape[0]):
        total += state[i] * state[i]
    if not math.isfinite(total) or total > EXPLODING * EXPLODING:
        return ST_PLANT_STATE
    if section_collapsed(state):
        return ST_SECTION_LENGTH
    for i in range(Fctl.shape[0]):
        Fctl[i] = 0.0 if ignored else Ftrue[i]
    return 0


def stepped_after_control(st, loop, law, ext_ref, row, cmd):
    """After the controller's step (status st): the row's force and contact columns; status 1 if T1, T2 or
    u2 is not finite, 4 on a runaway row.  If still 0: ref <- ext_ref (12,) if given, else (servo)
    `servo_reference_step`, and cmd (26,) <- [T1, T2, ref, sensed q2].  Returns the status."""
    _x, _n, _s, Ftrue, Fsens, cinfo, _i, ref, dt, servo = loop
    T1, T2, u2, sensed = law[0], law[1], law[2], law[9]
    for i in range(4):
        row[R_FT + i] = Ftrue[i]
        row[R_FS + i] = Fsens[i]
    for i in range(CONTACT_INFO):
        row[R_CI + i] = cinfo[i]
    for v in (T1, T2, u2):
        for i in range(v.shape[0]):
            if st == 0 and not math.isfinite(v[i]):
                st = ST_NONFINITE
    if st == 0 and runaway(row):
        st = ST_RUNAWAY
    if st != 0:
        return st
    if ext_ref.shape[0] > 0:
        for i in range(12):
            ref[i] = ext_ref[i]
    elif servo:
        servo_reference_step(ref, u2, dt)
    cmd[0] = T1[0]
    cmd[1] = T1[1]
    for i in range(6):
        cmd[2 + i] = T2[i]
    for i in range(12):
        cmd[8 + i] = ref[i]
    for i in range(6):
        cmd[20 + i] = sensed[4 + i]
    return 0


def stepped_paper_step(k, model, loop, law, row, cmd):
    """`stepped_state_check`, `control_step`, `stepped_after_control` in one call: (state status, step
    status); a non-zero state status: nothing recorded."""
    s0 = stepped_state_check(loop)
    if s0 != 0:
        return s0, 0
    state, noise, scale, _Ft, F, _c, _i, ref, dt, _servo = loop
    st = control_step(k, k * dt, model, state, noise, scale, F, law, row)
    return 0, stepped_after_control(st, loop, law, ref[0:0], row, cmd)


KERNELS = ("runaway", "section_collapsed", "servo_reference_step", "ring_index", "add_noise",
           "add_noise_channel", "sense_state", "record_row", "control_step", "desired", "analytic_sense",
           "analytic_command", "analytic_advance", "analytic_chunk", "stepped_state_check",
           "stepped_after_control", "stepped_paper_step")
