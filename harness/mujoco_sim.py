"""Closed loop on the MuJoCo plant.

The controllers run on the nominal analytic models (Scenario.master/slave); MuJoCo simulates the
plant built from Scenario.plant (its own parameters, segments, actuation).  The per-step work is
one compiled kernel (`harness.loop_kernels.mujoco_chunk`) that also calls MuJoCo's C `mj_step`, so no
Python runs per step.  MuJoCo's auto-reset on instability is disabled: bad accelerations leave NaN or
exploding states that the kernel detects, and every MuJoCo warning is counted and reported.

After the loop, the recorded joint positions are replayed through `mj_kinematics` to obtain the
MuJoCo tip site (x2_plant), the slave segment body poses and the master joint positions for the
recording (this keeps geometry bookkeeping out of the control loop).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from controllers import slave as slave_model

from .config import Scenario
from .fast import K
from .plant_model import ChainMap, build_model
from .sim import (
    CHUNK,
    STATUS_TEXT,
    STOP,
    _meta,
    _progress_bar,
    common_arrays,
    initial_state,
    noise_table,
)
from .trajectory import ROW_WIDTH, Trajectory

WARNINGS = [w for name, w in mujoco.mjtWarning.__members__.items() if name != "mjNWARNING"]


def warning_counts(d: mujoco.MjData) -> dict[str, int]:
    """Non-zero MuJoCo warning counters by name."""
    out = {}
    for name, w in mujoco.mjtWarning.__members__.items():
        if name == "mjNWARNING":
            continue
        n = int(d.warning[int(w)].number)
        if n:
            out[name] = n
    return out


def make_plant(scn: Scenario) -> tuple[mujoco.MjModel, mujoco.MjData, ChainMap]:
    """Compiled plant model, data at the scenario's initial state, and its ChainMap."""
    m, cmap = build_model(scn.plant_master, scn.plant_slave, scn.plant)
    m.opt.timestep = scn.plant.physics_dt
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    d = mujoco.MjData(m)
    s0 = initial_state(scn)
    d.qpos[cmap.master_qpos_adr] = s0[0:2]
    d.qvel[cmap.master_dof_adr] = s0[2:4]
    cmap.set_q2(d, s0[4:10], s0[10:16])
    mujoco.mj_forward(m, d)
    return m, d, cmap


def simulate_mujoco(scn: Scenario, progress: bool = False) -> Trajectory:
    """Run the scenario on the MuJoCo plant; returns the Trajectory (possibly cut short)."""
    m, d, cmap = make_plant(scn)
    n = scn.n_steps
    a = common_arrays(scn)
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    qpos_hist = np.zeros((n, m.nq))
    servo = scn.plant.actuation == "servo"
    nchain = cmap.n_chain
    kv_over_kp = (np.divide(cmap.servo_kv, cmap.servo_kp, out=np.zeros(nchain), where=cmap.servo_kp > 0)
                  if servo else np.zeros(nchain))
    s0 = initial_state(scn)
    ref = np.concatenate([s0[4:10], s0[10:16]])  # servo reference [q_ref, dq_ref]
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 2 + 2 * nchain))
    captured: list[str] = []
    mujoco.set_mju_user_warning(lambda msg: captured.append(str(msg)))
    bar = _progress_bar(progress, n, f"MuJoCo plant (N={cmap.n_segments}, {scn.plant.actuation})")
    status, done, k = 0, 0, 0
    interrupted = False
    warned: dict[str, int] = {}
    t0 = time.perf_counter()
    try:
        while k < n:
            k1 = min(n, k + CHUNK)
            status, mdone = K.mujoco_chunk(
                m._address, d._address, k, k1, scn.substeps, scn.control_dt, d.qpos, d.qvel, d.ctrl,
                d.qfrc_applied, cmap.master_qpos_adr, cmap.master_dof_adr, cmap.master_actuator_ids,
                cmap.chain_qpos_adr, cmap.chain_dof_adr, cmap.chain_actuator_ids, cmap.R, cmap.C, cmap.L0,
                cmap.elastic_args, servo, scn.plant.servo_feedforward, kv_over_kp, a["traj"], noise,
                scale, a["F"], a["mpk_c"], a["spk_c"], a["nodes"], a["weights"], a["gains"], a["spec"],
                ref, cmdbuf, delay, rows[k:k1], qpos_hist[k:k1])
            done = k + mdone
            if bar is not None:
                bar.update(mdone)
            warned = warning_counts(d)
            if status != 0:
                break
            if warned:  # any MuJoCo warning stops the run: it must never pass silently
                status = 6
                break
            k = k1
            if STOP.is_set():
                interrupted = True
                break
    finally:
        mujoco.set_mju_user_warning(None)
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    traj = Trajectory.from_rows(rows[:done])
    meta = _meta(scn, wall)
    traj.meta.update(meta)
    traj.meta.update(_plant_geometry(scn, m, cmap, qpos_hist[:done], traj))
    traj.meta["mujoco_warnings"] = int(sum(warned.values()))
    traj.meta["mujoco_warning_counts"] = warned
    traj.meta["mujoco_warning_text"] = captured[:20]
    if status != 0:
        traj.status = "diverged"
        t_end = traj.t[-1] if done else 0.0
        cause = STATUS_TEXT.get(status, "unknown")
        if warned:
            cause += " (" + ", ".join(f"{k_}: {v}" for k_, v in warned.items()) + ")"
            if captured:
                cause += f"; MuJoCo says: {captured[0].strip()}"
        traj.message = f"{cause} at t = {t_end:.4f} s"
    elif interrupted:
        traj.status = "interrupted"
        traj.message = f"interrupted at t = {traj.t[-1]:.4f} s"
    return traj


def _plant_geometry(scn: Scenario, m: mujoco.MjModel, cmap: ChainMap, qpos_hist: np.ndarray,
                    traj: Trajectory) -> dict:
    """Replay kinematics: MuJoCo tip site (x2_plant), slave body poses, master joint positions."""
    n = qpos_hist.shape[0]
    d = mujoco.MjData(m)
    chain_bodies = list(dict.fromkeys(int(m.jnt_bodyid[j]) for j in
                                      [i for i in range(m.njnt) if m.jnt_qposadr[i] in set(cmap.chain_qpos_adr)]))
    shoulder = int(m.jnt_bodyid[m.joint("master_shoulder_joint").id])
    elbow = int(m.jnt_bodyid[m.joint("master_elbow_joint").id])
    body_pos = np.zeros((n, len(chain_bodies), 3))
    body_quat = np.zeros((n, len(chain_bodies), 4))
    master_pos = np.zeros((n, 3, 3))
    tip = np.zeros((n, 3))
    for k in range(n):
        d.qpos[:] = qpos_hist[k]
        mujoco.mj_kinematics(m, d)
        body_pos[k] = d.xpos[chain_bodies]
        body_quat[k] = d.xquat[chain_bodies]
        master_pos[k, 0] = d.xanchor[m.joint("master_shoulder_joint").id] if k == 0 else master_pos[0, 0]
        master_pos[k, 1] = d.xpos[elbow]
        master_pos[k, 2] = d.site_xpos[cmap.master_site_id]
        tip[k] = d.site_xpos[cmap.tip_site_id]
    del shoulder
    base = np.asarray(cmap.octarm_base_pos)
    traj.x2_plant = np.stack([tip[:, 0] - base[0], tip[:, 2] - base[2]], axis=1)
    traj.body_pos = body_pos
    traj.body_quat = body_quat
    traj.master_pos = master_pos
    # analytic backbone of the sensed q2, in world coordinates (for the overlay)
    P = 8
    bb = np.zeros((n, 3 * P + 1, 3))
    for k in range(n):
        pts = slave_model.backbone(scn.slave, traj.q2[k], P)
        bb[k, :, 0] = base[0] + pts[:, 0]
        bb[k, :, 1] = base[1]
        bb[k, :, 2] = base[2] + pts[:, 1]
    return {
        "master_base": tuple(float(v) for v in cmap.master_base_pos),
        "slave_base": tuple(float(v) for v in base),
        "segments": cmap.n_segments, "actuation": cmap.actuation, "enforce_cc": cmap.enforce_cc,
        "body_names": [m.body(b).name for b in chain_bodies], "backbone": bb,
    }
