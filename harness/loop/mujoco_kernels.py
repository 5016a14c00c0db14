"""MuJoCo-plant loop kernels (numba-compatible): the control loop `mujoco_chunk`, its sensing and command
maps, the recording geometry.  Arguments: the groups of `mujoco_loop.plant_groups`."""

from __future__ import annotations

import numpy as np

from controllers.cc import backbone_points
from controllers.master import master_kernel
from controllers.status import ST_MUJOCO_STATE, ST_MUJOCO_WARNING, ST_OK, ST_SECTION_LENGTH
from harness.loop.force_kernels import CONTACT_INFO, operator_target, read_contact, sense_forces
from harness.loop.kernels import (
    EXPLODING,
    R_CI,
    R_FS,
    R_FT,
    R_HAND,
    bind,
    loop_chunk,
    section_collapsed,
    servo_reference_step,
)
from harness.loop.native import MJ_KINEMATICS_FN, MJ_STEP_FN, copy_geometry, mj_call
from harness.plant.chain_map import (
    chain_elastic_correction,
    chain_force_from_T2,
    chain_joints_from_q2,
    chain_joints_rate_add,
    chain_sense,
    muscle_commands,
)


def sense_mujoco(master, chain, state):
    """True (noise-free) state (16,) [q1, dq1, q2, dq2] from MuJoCo's joints."""
    qpos, qvel, m_qadr, m_dadr = master[0], master[1], master[2], master[3]
    c_qadr, c_dadr, R, _C, L0, _e, qc, vc, _corr = chain
    for i in range(2):
        state[i] = qpos[m_qadr[i]]
        state[2 + i] = qvel[m_dadr[i]]
    for c in range(c_qadr.shape[0]):
        qc[c] = qpos[c_qadr[c]]
        vc[c] = qvel[c_dadr[c]]
    chain_sense(qc, vc, R, L0, state[4:10], state[10:16])


def mujoco_state_status(state):
    """Status of the sensed true state (16,) of the MuJoCo plant: ST_MUJOCO_STATE if an entry is not finite
    or above EXPLODING in magnitude, ST_SECTION_LENGTH if a section length is <= 0, else ST_OK."""
    for i in range(16):
        if not np.isfinite(state[i]) or abs(state[i]) > EXPLODING:
            return ST_MUJOCO_STATE
    if section_collapsed(state):
        return ST_SECTION_LENGTH
    return ST_OK


def chain_commands(act, q2s, T2, cmd):
    """The chain's part of cmd = [master torque (2), chain ctrl (n), feed-forward force (n)] for T2 at the
    sensed q2s.  Torque: ctrl = virtual-work map of T2 at q2s.  Servo: ctrl = joints(q_ref) + (kv/kp)
    A(q_ref) dq_ref, feed-forward = the map of T2 at q_ref (if enabled).  Muscle: ctrl[0:6] =
    `chain_map.muscle_commands` (nsat[0] += the groups outside [0, F_max])."""
    servo, feedforward, _dt, C, R, L0, kv_over_kp, muscle, ref, nsat = act
    n = C.shape[0]
    radius, max_force = muscle
    if radius.shape[0] > 0:
        for c in range(n):
            cmd[2 + n + c] = 0.0
        nsat[0] += muscle_commands(q2s, T2, radius, max_force, cmd[2:8])
    elif servo:
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


def master_grip(master, operator):
    """The plant master's tip xm, vm = J1 dq1 (task frame) and J1 from MuJoCo's joints; with the operator,
    the grip force on the handle F1op = kg (x_h - x_m) + cg (v_h - v_m) (op = [mass, k, c, kg, cg], hand =
    [x_h (2), v_h (2)])."""
    qpos, qvel, m_qadr, m_dadr, mpk_p, q1, dq1, xm, vm, J1, Jd1, M1, N1 = master
    op_on, op, _targets, hand, _target, F1op = operator
    for i in range(2):
        q1[i] = qpos[m_qadr[i]]
        dq1[i] = qvel[m_dadr[i]]
    master_kernel(mpk_p, q1, dq1, xm, J1, Jd1, M1, N1)
    for i in range(2):
        vm[i] = J1[i, 0] * dq1[0] + J1[i, 1] * dq1[1]
    if op_on:
        for i in range(2):
            F1op[i] = op[3] * (hand[i] - xm[i]) + op[4] * (hand[2 + i] - vm[i])


def mujoco_sense(k, state, r, p):
    """The true state from MuJoCo's joints (status 6, 5), the contact and operator forces, the sensed F
    into the row, the qpos history."""
    _mj, master, chain, sensing, operator, rec, _act = p
    (sensordata, cadr, cpts, nopts, Fconst, fmode, fnoise, fstd, falpha, fdelay, fbuf, ffilt, F2c,
     Ftrue) = sensing
    qpos, F1op, hand, qpos_hist = master[0], operator[5], operator[3], rec[0]
    sense_mujoco(master, chain, state)
    st = mujoco_state_status(state)
    if st != ST_OK:
        return st
    read_contact(sensordata, cadr, F2c, r[R_CI:R_CI + CONTACT_INFO], cpts[k] if cpts.shape[0] > 0 else nopts)
    if operator[0]:
        master_grip(master, operator)
    for j in range(2):
        Ftrue[j] = Fconst[j] + F1op[j]
        Ftrue[2 + j] = Fconst[2 + j] + F2c[j]
    sense_forces(Ftrue, k, fmode, fnoise, fstd, falpha, fdelay, fbuf, ffilt, r[R_FS:R_FS + 4])
    for j in range(4):
        r[R_FT + j] = Ftrue[j]
    r[R_HAND] = hand[0]
    r[R_HAND + 1] = hand[1]
    if qpos_hist.shape[0] > 0:
        for j in range(qpos.shape[0]):
            qpos_hist[k, j] = qpos[j]
    return ST_OK


def mujoco_command(slot, law, p):
    """The step's command vector into its ring slot (`chain_commands` at the sensed q2, after the servo
    reference's step)."""
    act = p[6]
    T1, u2, sensed = law[0], law[2], law[9]
    slot[0] = T1[0]
    slot[1] = T1[1]
    if act[0]:
        servo_reference_step(act[8], u2, act[2])
    chain_commands(act, sensed[4:10], law[1], slot)


def mujoco_advance(k, st, use, state, law, p):
    """`substeps` x (operator and F1 forces, elastic correction, mj_step) with the commands `use`; a failed
    step (st != 0) is not stepped (its geometry row from its kinematics).  Status 7 on a MuJoCo warning."""
    mj, master, chain, sensing, operator, rec, _act = p
    mptr, dptr, mjfn, substeps, dt, ctrl, qfrc, m_act, c_act, wnum = mj
    c_qadr, c_dadr, R, C, L0, eargs, qc, vc, corr = chain
    op_on, op, targets, hand, target, F1op = operator
    qpos_hist, cmd_log, geo_in, geo_out = rec
    qpos, m_dadr, J1, Fconst = master[0], master[3], master[9], sensing[4]
    live = geo_out[0].shape[0] > 0
    if st != 0:
        if live:
            mj_call(mjfn[MJ_KINEMATICS_FN], mptr, dptr)
            copy_geometry(geo_in, k, geo_out)
        return st
    n = C.shape[0]
    nu = ctrl.shape[0]
    for j in range(2):
        ctrl[m_act[j]] = use[j]
    for c in range(c_act.shape[0]):
        ctrl[c_act[c]] = use[2 + c]
    apply1 = op_on or Fconst[0] != 0.0 or Fconst[1] != 0.0
    hphys = dt / substeps
    for s in range(substeps):
        if apply1:  # operator's grip (+ constant F1) on the master handle, J1^T F1
            if s > 0 or not op_on:  # at s = 0 with the operator: J1 and F1op are the step's own
                master_grip(master, operator)
            if op_on:  # the hand: semi-implicit Euler, m a = k (target - x_h) - c v_h - F1op (the reaction)
                operator_target(targets, k * dt + s * hphys, target)
                for j in range(2):
                    acc = (op[1] * (target[j] - hand[j]) - op[2] * hand[2 + j] - F1op[j]) / op[0]
                    hand[2 + j] += acc * hphys
                    hand[j] += hand[2 + j] * hphys
            for j in range(2):  # J1^T (F1 + F1op), J1 of the last `master_grip`
                qfrc[m_dadr[j]] = J1[0, j] * (Fconst[0] + F1op[0]) + J1[1, j] * (Fconst[1] + F1op[1])
        for c in range(n):
            qc[c] = qpos[c_qadr[c]]
        chain_elastic_correction(qc, *eargs, corr)
        for c in range(n):
            qfrc[c_dadr[c]] = use[2 + n + c] + corr[c]
        if cmd_log.shape[0] > 0:
            lr = cmd_log[k * substeps + s]
            for j in range(nu):
                lr[j] = ctrl[j]
            for j in range(qfrc.shape[0]):
                lr[nu + j] = qfrc[j]
        mj_call(mjfn[MJ_STEP_FN], mptr, dptr)
        if live and s == 0:
            copy_geometry(geo_in, k, geo_out)
        for w in range(wnum.shape[0]):
            if wnum[w] != 0:  # any MuJoCo warning stops the run: it must never pass silently
                return ST_MUJOCO_WARNING
    return ST_OK


# the MuJoCo plant's loop (`mujoco_loop`); plant: `plant_groups`'
mujoco_chunk = bind(loop_chunk, "mujoco_chunk", plant_sense=mujoco_sense, plant_command=mujoco_command,
                    plant_advance=mujoco_advance)


def replay_commands(mptr, dptr, mjfn, ctrl, qfrc, cmd_log):
    """Raw MuJoCo: for each row of cmd_log (rows, nu + nv), [ctrl, qfrc_applied] <- row, mj_step."""
    nu = ctrl.shape[0]
    nv = qfrc.shape[0]
    for r in range(cmd_log.shape[0]):
        for i in range(nu):
            ctrl[i] = cmd_log[r, i]
        for i in range(nv):
            qfrc[i] = cmd_log[r, nu + i]
        mj_call(mjfn[MJ_STEP_FN], mptr, dptr)


# the kernels that allocate on the heap (run-time sizes), compiled with numba's runtime (harness.loop.fast)
HEAP_KERNELS = ("backbone_world",)
KERNELS = ("sense_mujoco", "mujoco_state_status", "chain_commands", "master_grip", "mujoco_sense",
           "mujoco_command", "mujoco_advance", "mujoco_chunk", "replay_commands", "kinematics_replay",
           "backbone_world")


# --- recording geometry after the loop ---------------------------------------------------------------
def kinematics_replay(mptr, dptr, mjfn, qpos, qpos_hist, geo_in, geo_out):
    """For each row of qpos_hist (n, nq): qpos <- row, mj_kinematics, `copy_geometry`."""
    nq = qpos.shape[0]
    for k in range(qpos_hist.shape[0]):
        for i in range(nq):
            qpos[i] = qpos_hist[k, i]
        mj_call(mjfn[MJ_KINEMATICS_FN], mptr, dptr)
        copy_geometry(geo_in, k, geo_out)


def backbone_world(q2, n_per_section, base, out):
    """Analytic backbone (`controllers.cc.backbone_points`) of every row of q2 (n, 6), world frame:
    out (n, 3 P + 1, 3) = (base_x + X, base_y, base_z + Z)."""
    npts = 3 * n_per_section + 1
    pts = np.empty((npts, 2))
    for k in range(q2.shape[0]):
        backbone_points(q2[k], n_per_section, pts)
        for r in range(npts):
            out[k, r, 0] = base[0] + pts[r, 0]
            out[k, r, 1] = base[1]
            out[k, r, 2] = base[2] + pts[r, 1]

