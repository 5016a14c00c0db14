"""Per-step loop kernels (numba-compatible; compiled by `harness.fast` together with controllers/).

Everything that happens once per control step and is not MuJoCo's `mj_step` lives here, fused, so
that the Python side of the loop is one kernel call plus `mj_step`:
  sensing noise -> master law -> slave law -> record row (and, for the analytic plant, RK4).

Status codes returned by the kernels (STATUS_TEXT in harness.sim):
0 ok, 1 non-finite state or command, 2 master Jacobian singular, 3 slave J2 J2^T singular,
4 runaway error (|e1| or |e2| above the limit), 5 slave section length <= 0, 6 non-finite or
exploding MuJoCo state, 7 a MuJoCo warning (counted by MuJoCo in mjData.warning; checked after
every mj_step, so the run stops at the step that raised it).
"""

from __future__ import annotations

import numpy as np

from controllers.cc import backbone_points, tip_kinematics
from controllers.control import (
    DET_MIN,
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
    master_control_kernel,
    slave_control_kernel,
)
from controllers.master import master_kernel
from controllers.slave import mass_nle_kernel
from controllers.subtasks import limits_kernel
from harness.plant_model import (
    chain_elastic_correction,
    chain_force_from_T2,
    chain_joints_from_q2,
    chain_joints_rate_add,
    chain_sense,
)

# record row layout (must match harness.trajectory.ROW_FIELDS)
R_T, R_Q1, R_DQ1, R_Q2, R_DQ2, R_XD, R_X1, R_X2 = 0, 1, 3, 5, 11, 17, 19, 21
R_E1, R_E2, R_DE1, R_DE2, R_BETA, R_YA, R_DEN, R_T1, R_T2, R_U2 = 23, 25, 27, 29, 31, 32, 33, 39, 41, 47
ROW_W = 53
RUNAWAY = 1.0  # m: |e1| or |e2| beyond this is a runaway (the workspace is ~1 m)


def cholesky_solve(A, b, out):
    """Solve A x = b for symmetric positive definite A (n,n) by Cholesky; returns False if not SPD."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if s <= 0.0:
                    return False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]
    return True


def add_noise(state, noise_row, scale, out):
    """AWGN at a given SNR on each fed-back vector (q1, dq1, q2, dq2 = state[0:2], [2:4], [4:10],
    [10:16]): std = rms(vector) * scale, scale = 10^(-SNR/20) (signal power measured per step)."""
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


def control_laws(mpk, spk, nodes, weights, gains, spec, sensed, xd, dxd, ddxd, F, T1, T2, u2, deN,
                 minfo, sinfo):
    """Both controllers on a sensed state (16,) = [q1, dq1, q2, dq2].  Returns a status code."""
    q1 = sensed[0:2]
    dq1 = sensed[2:4]
    q2 = sensed[4:10]
    dq2 = sensed[10:16]
    det1 = master_control_kernel(mpk, gains, q1, dq1, xd, dxd, ddxd, F[0:2], T1, minfo)
    if det1 == 0.0:
        return 2
    det2 = slave_control_kernel(spk, nodes, weights, gains, spec, q2, dq2, minfo[0:2], minfo[8:10],
                                minfo[6:8], F[2:4], T2, u2, deN, sinfo)
    if det2 <= DET_MIN:
        return 3
    return 0


def record_row(t, state, xd, dxd, mpk, gains, spec, T1, T2, u2, deN, row):
    """Fill one record row from the noise-free state (16,) and the commands."""
    row[R_T] = t
    for i in range(16):
        row[R_Q1 + i] = state[i]
    x1 = np.empty(2)
    J1 = np.empty((2, 2))
    Jd1 = np.empty((2, 2))
    M1 = np.empty((2, 2))
    N1 = np.empty(2)
    master_kernel(mpk, state[0:2], state[2:4], x1, J1, Jd1, M1, N1)
    x2 = np.empty(2)
    J2 = np.empty((2, 6))
    H = np.empty((2, 6, 6))
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
        g = np.empty(6)
        gd = np.empty(6)
        beta += spec[1] * limits_kernel(spec, q2, np.zeros(6), g, gd)
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


def control_step(t, state, traj, noise, k, noise_scale, mpk_c, spk_c, nodes, weights, gains, spec, F,
                 xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, row):
    """One control step at time t on the true state (16,): x_d(t) into xd, dxd, ddxd; the sensed
    state (true state + AWGN noise_scale * noise[k], noise (n, 16) read only if noise_scale > 0) into
    sensed; both laws (control_laws); the record row of the true state into row.  Returns
    control_laws' status."""
    desired(traj, t, xd, dxd, ddxd)
    if noise_scale > 0.0:
        add_noise(state, noise[k], noise_scale, sensed)
    else:
        for i in range(16):
            sensed[i] = state[i]
    st = control_laws(mpk_c, spk_c, nodes, weights, gains, spec, sensed, xd, dxd, ddxd, F,
                      T1, T2, u2, deN, minfo, sinfo)
    if noise_scale == 0.0 and st == 0:  # laws ran on the true state: reuse their kinematics
        record_row_info(t, state, xd, dxd, minfo, sinfo, T1, T2, u2, deN, row)
    else:
        record_row(t, state, xd, dxd, mpk_c, gains, spec, T1, T2, u2, deN, row)
    return st


def plant_accel(mpk, spk, nodes, weights, s, T1, T2, F, acc):
    """Analytic plant forward dynamics: acc (16,) = d/dt [q1, dq1, q2, dq2].  False if not SPD."""
    x = np.empty(2)
    J1 = np.empty((2, 2))
    Jd1 = np.empty((2, 2))
    M1 = np.empty((2, 2))
    N1 = np.empty(2)
    master_kernel(mpk, s[0:2], s[2:4], x, J1, Jd1, M1, N1)
    rhs1 = np.empty(2)
    for i in range(2):
        rhs1[i] = T1[i] - N1[i] + J1[0, i] * F[0] + J1[1, i] * F[1]
    dd1 = np.empty(2)
    ok1 = cholesky_solve(M1, rhs1, dd1)
    M2 = np.empty((6, 6))
    N2 = np.empty(6)
    mass_nle_kernel(spk, s[4:10], s[10:16], nodes, weights, M2, N2)
    rhs2 = np.empty(6)
    if F[2] != 0.0 or F[3] != 0.0:
        x2 = np.empty(2)
        J2 = np.empty((2, 6))
        H = np.empty((2, 6, 6))
        tip_kinematics(s[4:10], s[10:16], 1, x2, J2, H, H)
        for a in range(6):
            rhs2[a] = T2[a] - N2[a] + J2[0, a] * F[2] + J2[1, a] * F[3]
    else:
        for a in range(6):
            rhs2[a] = T2[a] - N2[a]
    dd2 = np.empty(6)
    ok2 = cholesky_solve(M2, rhs2, dd2)
    acc[0] = s[2]
    acc[1] = s[3]
    acc[2] = dd1[0]
    acc[3] = dd1[1]
    for a in range(6):
        acc[4 + a] = s[10 + a]
        acc[10 + a] = dd2[a]
    return ok1 and ok2


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


def analytic_chunk(state, k0, k1, dt, nsub, continuous, traj, noise, noise_scale, F,
                   mpk_c, spk_c, mpk_p, spk_p, nodes, weights, gains, spec, rows):
    """Run control steps k0..k1-1 of the closed loop on the analytic plant, in place on state (16,).

    Controller uses the nominal packed params (mpk_c, spk_c), the plant its own (mpk_p, spk_p).
    Zero-order hold of the commands over the control step (nsub RK4 steps of dt/nsub) unless
    `continuous`, where both laws are evaluated in every RK4 stage on the true state (no noise).
    Returns (status, number of completed steps)."""
    T1 = np.zeros(2)
    T2 = np.zeros(6)
    u2 = np.zeros(6)
    deN = np.zeros(6)
    minfo = np.empty(MASTER_INFO)
    sinfo = np.empty(SLAVE_INFO)
    sensed = np.empty(16)
    xd = np.empty(2)
    dxd = np.empty(2)
    ddxd = np.empty(2)
    k1s = np.empty(16)
    k2s = np.empty(16)
    k3s = np.empty(16)
    k4s = np.empty(16)
    tmp = np.empty(16)
    h = dt / nsub
    for k in range(k0, k1):
        t = k * dt
        st = control_step(t, state, traj, noise, k, noise_scale, mpk_c, spk_c, nodes, weights, gains, spec, F,
                          xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, rows[k - k0])
        if st != 0:
            return st, k - k0 + 1
        for j in range(nsub):
            ts = t + j * h
            # RK4 stage 1
            if continuous:
                desired(traj, ts, xd, dxd, ddxd)
                st = control_laws(mpk_c, spk_c, nodes, weights, gains, spec, state, xd, dxd, ddxd, F,
                                  T1, T2, u2, deN, minfo, sinfo)
                if st != 0:
                    return st, k - k0 + 1
            if not plant_accel(mpk_p, spk_p, nodes, weights, state, T1, T2, F, k1s):
                return 1, k - k0 + 1
            for i in range(16):
                tmp[i] = state[i] + 0.5 * h * k1s[i]
            if continuous:
                desired(traj, ts + 0.5 * h, xd, dxd, ddxd)
                control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                             T1, T2, u2, deN, minfo, sinfo)
            if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, F, k2s):
                return 1, k - k0 + 1
            for i in range(16):
                tmp[i] = state[i] + 0.5 * h * k2s[i]
            if continuous:
                control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                             T1, T2, u2, deN, minfo, sinfo)
            if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, F, k3s):
                return 1, k - k0 + 1
            for i in range(16):
                tmp[i] = state[i] + h * k3s[i]
            if continuous:
                desired(traj, ts + h, xd, dxd, ddxd)
                control_laws(mpk_c, spk_c, nodes, weights, gains, spec, tmp, xd, dxd, ddxd, F,
                             T1, T2, u2, deN, minfo, sinfo)
            if not plant_accel(mpk_p, spk_p, nodes, weights, tmp, T1, T2, F, k4s):
                return 1, k - k0 + 1
            for i in range(16):
                state[i] += h / 6.0 * (k1s[i] + 2.0 * k2s[i] + 2.0 * k3s[i] + k4s[i])
        for i in range(16):
            if not np.isfinite(state[i]):
                return 1, k - k0 + 1
        for i in range(3):
            if state[4 + i] <= 0.0:
                return 5, k - k0 + 1
        r = rows[k - k0]
        if (abs(r[R_E1]) + abs(r[R_E1 + 1]) > RUNAWAY) or (abs(r[R_E2]) + abs(r[R_E2 + 1]) > RUNAWAY):
            return 4, k - k0 + 1
    return 0, k1 - k0


KERNELS = ("cholesky_solve", "add_noise", "control_laws", "record_row", "record_row_info", "control_step",
           "plant_accel", "desired", "analytic_chunk")


# =============================================================================================
# MuJoCo plant: the whole control loop compiled, calling MuJoCo's C functions by address
# =============================================================================================
# The C functions `void f(const mjModel*, mjData*)` are called through a function pointer passed as
# an argument (`mjfn` = MJ_FUNCS: [mj_step, mj_kinematics] addresses of this process), not through a
# ctypes object, so that numba can cache the compiled loop on disk (a ctypes global would bake this
# process' addresses into the code and make it uncacheable: ~3 s of compilation in every process).
MJ_STEP_FN, MJ_KINEMATICS_FN = 0, 1


def _mj_addresses():
    import ctypes
    import glob
    import os

    import mujoco

    libs = sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))
    if not libs:  # pragma: no cover - other platforms
        return np.zeros(2, dtype=np.int64)
    lib = ctypes.CDLL(libs[0])
    names = ("mj_step", "mj_kinematics")
    return np.array([ctypes.cast(getattr(lib, f), ctypes.c_void_p).value for f in names], dtype=np.int64)


MJ_FUNCS = _mj_addresses()  # pass to the kernels below; never use as a global inside them


def mj_call(fn, mptr, dptr):
    """Call the MuJoCo C function at address fn with (mjModel*, mjData*) (interpreted: ctypes;
    compiled: a direct indirect call, see the numba overload below)."""
    import ctypes

    if fn == 0:  # pragma: no cover
        raise RuntimeError("MuJoCo's shared library was not found (libmujoco.so*)")
    ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(int(fn))(mptr, dptr)


try:  # compiled form of mj_call (numba is optional: without it the kernels run interpreted)
    from llvmlite import ir as _ir
    from numba import types as _nbt
    from numba.extending import intrinsic as _intrinsic
    from numba.extending import overload as _overload

    @_intrinsic
    def _mj_call_ptr(typingctx, fn, mptr, dptr):
        sig = _nbt.void(fn, mptr, dptr)

        def codegen(context, builder, signature, args):
            vp = _ir.IntType(8).as_pointer()
            fnty = _ir.FunctionType(_ir.VoidType(), [vp, vp])
            f = builder.inttoptr(args[0], fnty.as_pointer())
            builder.call(f, [builder.inttoptr(args[1], vp), builder.inttoptr(args[2], vp)])
            return context.get_dummy_value()

        return sig, codegen

    @_overload(mj_call)
    def _mj_call_overload(fn, mptr, dptr):
        def impl(fn, mptr, dptr):
            _mj_call_ptr(fn, mptr, dptr)

        return impl
except ImportError:  # pragma: no cover
    pass


def sense_mujoco(qpos, qvel, m_qadr, m_dadr, c_qadr, c_dadr, R, L0, qc, vc, state):
    """True (noise-free) state (16,) [q1, dq1, q2, dq2] from MuJoCo joints; qc, vc (n_chain,) work."""
    for i in range(2):
        state[i] = qpos[m_qadr[i]]
        state[2 + i] = qvel[m_dadr[i]]
    for c in range(c_qadr.shape[0]):
        qc[c] = qpos[c_qadr[c]]
        vc[c] = qvel[c_dadr[c]]
    chain_sense(qc, vc, R, L0, state[4:10], state[10:16])


def mujoco_commands(servo, feedforward, dt, q2s, T2, u2, ref, C, R, L0, kv_over_kp, cmd):
    """Command vector cmd = [master torque (2), chain ctrl (n), chain feedforward force (n)].

    Torque actuation: chain ctrl = virtual-work map of T2 at the sensed q2s (motors).
    Servo actuation: integrate the reference q2 with u2 (semi-implicit Euler, ref = [q_ref, dq_ref]),
    ctrl = joints(q_ref) + (kv/kp) A(q_ref) dq_ref (position servo with velocity feed-forward folded
    into the target), feed-forward = virtual-work map of T2 at q_ref (if enabled)."""
    n = C.shape[0]
    if servo:
        for a in range(6):
            ref[6 + a] += u2[a] * dt
            ref[a] += ref[6 + a] * dt
        chain_joints_from_q2(ref[0:6], C, L0, cmd[2:2 + n])
        chain_joints_rate_add(ref[0:6], ref[6:12], C, kv_over_kp, cmd[2:2 + n])
        if feedforward:
            chain_force_from_T2(ref[0:6], T2, R, cmd[2 + n:2 + 2 * n])
        else:
            for c in range(n):
                cmd[2 + n + c] = 0.0
    else:
        chain_force_from_T2(q2s, T2, R, cmd[2:2 + n])
        for c in range(n):
            cmd[2 + n + c] = 0.0


def mujoco_chunk(mptr, dptr, mjfn, k0, k1, substeps, dt, qpos, qvel, ctrl, qfrc, m_qadr, m_dadr, m_act,
                 c_qadr, c_dadr, c_act, R, C, L0, eargs,
                 servo, feedforward, kv_over_kp, traj, noise, noise_scale, F, mpk_c, spk_c, nodes,
                 weights, gains, spec, ref, cmdbuf, delay, rows, qpos_hist, cmd_log, geo_in, geo_out, wnum):
    """Control steps k0..k1-1 on the MuJoCo plant (model/data pointers mptr, dptr; mjfn = MJ_FUNCS;
    qpos, qvel, ctrl, qfrc are numpy views of the same MjData).  Per step: sense -> noise -> both laws
    -> record -> commands (delayed by `delay` control steps through the ring buffer cmdbuf (delay+1, 2+2n)) ->
    `substeps` x (elastic correction + mj_step).  eargs: ChainMap.elastic_args (constant tuple).
    cmd_log (rows, nu + nv): if it has rows ((k1 - k0) * substeps), row (k - k0) * substeps + s receives
    [ctrl, qfrc] exactly as applied before that mj_step (for a raw-MuJoCo replay); 0 rows = off.
    Recording geometry: qpos_hist (k1 - k0, nq) receives qpos at the start of each step (0 rows = off),
    or, if geo_out = (body_pos, body_quat, master_pos, tip) has rows, `copy_geometry` fills them from the
    kinematics MuJoCo computed inside the first mj_step of the step (the start state: valid for the
    single-stage integrators, not RK4), geo_in = (xpos, xquat, site_xpos, xanchor, bodies, gids).
    wnum: view of MuJoCo's warning counters (mjData.warning.number), checked after every mj_step.
    Returns (status, completed steps); status 6 = non-finite or exploding MuJoCo state, 7 = a MuJoCo
    warning was raised during the last completed step (whose row is recorded)."""
    n = C.shape[0]
    state = np.empty(16)
    sensed = np.empty(16)
    qc = np.empty(n)
    vc = np.empty(n)
    corr = np.empty(n)
    T1 = np.zeros(2)
    T2 = np.zeros(6)
    u2 = np.zeros(6)
    deN = np.zeros(6)
    minfo = np.empty(MASTER_INFO)
    sinfo = np.empty(SLAVE_INFO)
    xd = np.empty(2)
    dxd = np.empty(2)
    ddxd = np.empty(2)
    nb = delay + 1
    log = cmd_log.shape[0] > 0
    hist = qpos_hist.shape[0] > 0
    live = geo_out[0].shape[0] > 0
    nu = ctrl.shape[0]
    nv = qfrc.shape[0]
    for k in range(k0, k1):
        sense_mujoco(qpos, qvel, m_qadr, m_dadr, c_qadr, c_dadr, R, L0, qc, vc, state)
        for i in range(16):
            if not np.isfinite(state[i]) or abs(state[i]) > 1e6:
                return 6, k - k0
        for i in range(3):
            if state[4 + i] <= 0.0:
                return 5, k - k0
        t = k * dt
        st = control_step(t, state, traj, noise, k, noise_scale, mpk_c, spk_c, nodes, weights, gains, spec, F,
                          xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, rows[k - k0])
        if hist:
            for i in range(qpos.shape[0]):
                qpos_hist[k - k0, i] = qpos[i]
        r = rows[k - k0]
        if st == 0 and ((abs(r[R_E1]) + abs(r[R_E1 + 1]) > RUNAWAY)
                        or (abs(r[R_E2]) + abs(r[R_E2 + 1]) > RUNAWAY)):
            st = 4
        if st != 0:
            if live:  # the last recorded step is not stepped: its kinematics explicitly
                mj_call(mjfn[MJ_KINEMATICS_FN], mptr, dptr)
                copy_geometry(geo_in, k - k0, geo_out)
            return st, k - k0 + 1
        slot = k % nb
        cmd = cmdbuf[slot]
        cmd[0] = T1[0]
        cmd[1] = T1[1]
        mujoco_commands(servo, feedforward, dt, sensed[4:10], T2, u2, ref, C, R, L0, kv_over_kp, cmd)
        use = cmdbuf[(k - delay) % nb] if k >= delay else cmdbuf[0]
        for i in range(2):
            ctrl[m_act[i]] = use[i]
        for c in range(n):
            ctrl[c_act[c]] = use[2 + c]
        for s in range(substeps):
            for c in range(n):
                qc[c] = qpos[c_qadr[c]]
            chain_elastic_correction(qc, *eargs, corr)
            for c in range(n):
                qfrc[c_dadr[c]] = use[2 + n + c] + corr[c]
            if log:
                lr = cmd_log[(k - k0) * substeps + s]
                for i in range(nu):
                    lr[i] = ctrl[i]
                for i in range(nv):
                    lr[nu + i] = qfrc[i]
            mj_call(mjfn[MJ_STEP_FN], mptr, dptr)
            if live and s == 0:
                copy_geometry(geo_in, k - k0, geo_out)
            for w in range(wnum.shape[0]):
                if wnum[w] != 0:  # any MuJoCo warning stops the run: it must never pass silently
                    return 7, k - k0 + 1
    return 0, k1 - k0


def replay_commands(mptr, dptr, mjfn, ctrl, qfrc, cmd_log):
    """Raw MuJoCo: for each row of cmd_log (rows, nu + nv) copy [ctrl, qfrc_applied] in and mj_step
    (the same physics steps as a logged `mujoco_chunk` run, without the harness)."""
    nu = ctrl.shape[0]
    nv = qfrc.shape[0]
    for r in range(cmd_log.shape[0]):
        for i in range(nu):
            ctrl[i] = cmd_log[r, i]
        for i in range(nv):
            qfrc[i] = cmd_log[r, nu + i]
        mj_call(mjfn[MJ_STEP_FN], mptr, dptr)


KERNELS = KERNELS + ("sense_mujoco", "mujoco_commands", "mujoco_chunk", "replay_commands")


# =============================================================================================
# Recording geometry, after the loop: MuJoCo kinematics replay and analytic backbone, compiled
# =============================================================================================
def copy_geometry(geo_in, row, geo_out):
    """Row `row` of the recording geometry from MuJoCo's current kinematics: geo_in = (xpos, xquat,
    site_xpos, xanchor (views of the MjData), bodies (nb,) chain body ids, gids = [elbow body, shoulder
    joint, master tip site, slave tip site]); geo_out = (body_pos (n, nb, 3), body_quat (n, nb, 4) wxyz,
    master_pos (n, 3, 3) = shoulder anchor, elbow, master tip; tip (n, 3) slave tip site)."""
    xpos, xquat, site_xpos, xanchor, bodies, gids = geo_in
    body_pos, body_quat, master_pos, tip = geo_out
    for b in range(bodies.shape[0]):
        src = bodies[b]
        for j in range(3):
            body_pos[row, b, j] = xpos[src, j]
        for j in range(4):
            body_quat[row, b, j] = xquat[src, j]
    for j in range(3):
        master_pos[row, 0, j] = xanchor[gids[1], j]
        master_pos[row, 1, j] = xpos[gids[0], j]
        master_pos[row, 2, j] = site_xpos[gids[2], j]
        tip[row, j] = site_xpos[gids[3], j]


def kinematics_replay(mptr, dptr, mjfn, qpos, qpos_hist, geo_in, geo_out):
    """For each row of qpos_hist (n, nq): qpos <- row, MuJoCo's C mj_kinematics, `copy_geometry`
    (qpos and geo_in views of the MjData at dptr)."""
    nq = qpos.shape[0]
    for k in range(qpos_hist.shape[0]):
        for i in range(nq):
            qpos[i] = qpos_hist[k, i]
        mj_call(mjfn[MJ_KINEMATICS_FN], mptr, dptr)
        copy_geometry(geo_in, k, geo_out)


def backbone_world(q2, n_per_section, base, out):
    """Analytic backbone (controllers.cc.backbone_points) of every row of q2 (n, 6) in world
    coordinates: out (n, 3 P + 1, 3) = (base_x + X, base_y, base_z + Z)."""
    npts = 3 * n_per_section + 1
    pts = np.empty((npts, 2))
    for k in range(q2.shape[0]):
        backbone_points(q2[k], n_per_section, pts)
        for r in range(npts):
            out[k, r, 0] = base[0] + pts[r, 0]
            out[k, r, 1] = base[1]
            out[k, r, 2] = base[2] + pts[r, 1]


KERNELS = KERNELS + ("copy_geometry", "kinematics_replay", "backbone_world")
