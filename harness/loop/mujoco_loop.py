"""Closed loop on the MuJoCo plant: the paper's law on the nominal models, one compiled kernel per chunk of
steps (`mujoco_kernels.mujoco_chunk`, calling MuJoCo's C `mj_step`).  Auto-reset is off: a bad state is
status 6 and any MuJoCo warning stops the run (7).  Recording geometry is copied after each step's first
mj_step (single-stage integrators) or replayed with `mj_kinematics` after the loop (RK4).  meta:
build_time, kernel_load_time, wall_time, geometry_time (s)."""

from __future__ import annotations

import time

import mujoco
import numpy as np

from controllers.status import Status
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import ChunkRun, RunModel, compile_model, noise_table, part_trajectory, progress_bar
from harness.loop.force_args import ForceArgs
from harness.loop.mj_warnings import WarningSink
from harness.loop.native import MJ_FUNCS
from harness.loop.trajectory import ROW_WIDTH, Trajectory
from harness.plant.chain_map import ChainMap
from harness.plant.mujoco_model import MujocoPlant

# control steps per compiled call (between progress, interrupt and warning checks; per live-view chunk)
MUJOCO_CHUNK = 1000
BACKBONE_POINTS = 8  # analytic backbone points per section in the recording
# integrators whose mj_step leaves the kinematics of the step's start state in MjData
LIVE_GEOMETRY_INTEGRATORS = ("euler", "implicit", "implicitfast")


def warning_counts(numbers: np.ndarray) -> dict[str, int]:
    """Non-zero MuJoCo warning counters by name (numbers: mjData.warning.number)."""
    return {name: int(numbers[int(w)]) for name, w in mujoco.mjtWarning.__members__.items()
            if name != "mjNWARNING" and int(numbers[int(w)])}


def actuation_args(cmap: ChainMap, servo: bool) -> tuple[np.ndarray, np.ndarray, tuple]:
    """(the chain's actuators in command order, kv / kp (n,) of the servos (zeros unless servo), muscle =
    (radius (3,), max_force (3,)) or two empty arrays) for `mujoco_kernels.chain_commands`."""
    n = cmap.n_chain
    kv_over_kp = (np.divide(cmap.servo_kv, cmap.servo_kp, out=np.zeros(n), where=cmap.servo_kp > 0) if servo
                  else np.zeros(n))
    if cmap.muscle_actuator_ids.shape[0]:
        muscle = (np.asarray(cmap.muscle_radius, float), np.asarray(cmap.muscle_max_force, float))
        return cmap.muscle_actuator_ids, kv_over_kp, muscle
    return cmap.chain_actuator_ids, kv_over_kp, (np.zeros(0), np.zeros(0))


def make_plant(scn: Scenario, plant: MujocoPlant | None = None, s0: np.ndarray | None = None
               ) -> tuple[mujoco.MjModel, mujoco.MjData, ChainMap]:
    """(mjModel, MjData at the initial state s0 (16,) (default: the scenario's), ChainMap) of `plant`."""
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, cmap = plant.model, plant.cmap
    m.opt.timestep = scn.plant.physics_dt
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    d = mujoco.MjData(m)
    if s0 is None:
        s0 = compile_model(scn).s0
    d.qpos[cmap.master_qpos_adr] = s0[0:2]
    d.qvel[cmap.master_dof_adr] = s0[2:4]
    cmap.set_q2(d, s0[4:10], s0[10:16])
    mujoco.mj_forward(m, d)
    return m, d, cmap


def simulate_mujoco(scn: Scenario, progress: bool = False, cmd_log: np.ndarray | None = None,
                    plant: MujocoPlant | None = None, on_chunk=None, model: RunModel | None = None
                    ) -> Trajectory:
    """The paper's law on the MuJoCo plant; returns the Trajectory (possibly cut short).  cmd_log: optional
    (n_steps * substeps, nu + nv) array receiving [ctrl, qfrc_applied] before every mj_step (a raw-MuJoCo
    replay); on_chunk: called with each finished chunk as a `Trajectory`; model: default compiled here."""
    a = model if model is not None else compile_model(scn)
    s0 = a.s0
    tb = time.perf_counter()
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, d, cmap = make_plant(scn, plant, s0)
    build_time = time.perf_counter() - tb
    n, sub = scn.n_steps, scn.substeps
    if cmd_log is None:
        cmd_log = np.zeros((0, m.nu + m.nv))
    elif cmd_log.shape != (n * sub, m.nu + m.nv):
        raise ValueError(f"cmd_log must have shape {(n * sub, m.nu + m.nv)}, got {cmd_log.shape}")
    log = cmd_log.shape[0] > 0
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    geo = Geometry(m, d, cmap, n, live=scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS)
    servo = scn.plant.actuation == "servo"
    ref = np.concatenate([s0[4:10], s0[10:16]])  # servo reference [q_ref, dq_ref]
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 2 + 2 * cmap.n_chain))
    force = ForceArgs(scn, m, d, cmap, plant.contact, n, s0, a.F)
    warned: dict[str, int] = {}
    wnum = d.warning.number  # view of MuJoCo's warning counters
    ctrl_ids, kv_over_kp, muscle = actuation_args(cmap, servo)
    nsat = np.zeros(1, dtype=np.int64)  # saturated muscle group-steps of the run
    plant_args = (m._address, d._address, MJ_FUNCS, sub, scn.control_dt, cmap.master_qpos_adr,
                  cmap.master_dof_adr, cmap.master_actuator_ids, cmap.chain_qpos_adr, cmap.chain_dof_adr,
                  ctrl_ids, cmap.R, cmap.C, cmap.L0, cmap.elastic_args, servo, scn.plant.servo_feedforward,
                  kv_over_kp, muscle)

    def chunk(k: int, k1: int):
        data = (d.qpos, d.qvel, d.ctrl, d.qfrc_applied, noise, scale, ref, cmdbuf, delay, rows[k:k1],
                geo.qpos_hist[k:k1], cmd_log[k * sub:k1 * sub] if log else cmd_log, geo.inputs,
                geo.outputs(k, k1), wnum, nsat)
        status, mdone = A.mujoco_chunk(k, k1, a, plant_args, data, force.args(k, k1))
        if wnum.any():
            warned.update(warning_counts(wnum))
            if status == 0:  # the kernel stops at the step that raised it; never pass silently
                status = Status.MUJOCO_WARNING
        return status, mdone

    tl = time.perf_counter()
    chunk(0, 0)  # no step: numba loads the kernel (on-disk cache) with the run's argument types
    load_time = time.perf_counter() - tl

    def part(k: int, done: int) -> None:
        piece = part_trajectory(scn, rows[k:done])
        geo.fill(piece, k, done)
        on_chunk(piece)

    bar = progress_bar(progress, n, f"MuJoCo plant (N={cmap.n_segments}, {scn.plant.actuation})")
    run = ChunkRun(n, MUJOCO_CHUNK, bar, part if on_chunk is not None else None)
    with WarningSink() as sink:  # MuJoCo's warning text raised by this run
        run.run(chunk)
    detail = ""
    if warned:
        detail = " (" + ", ".join(f"{k_}: {v}" for k_, v in warned.items()) + ")"
        if sink.text:
            detail += f"; MuJoCo says: {sink.text[0].strip()}"
    traj = run.trajectory(scn, rows, detail)
    if force.cpts.shape[0]:
        traj.contact_points = force.cpts[:run.done].copy()
    tg = time.perf_counter()
    geo.finish(traj, run.done, warned, int(nsat[0]))
    traj.meta.update(geometry_time=time.perf_counter() - tg, build_time=build_time,
                     kernel_load_time=load_time, mujoco_warning_text=sink.text[:20])
    return traj


def chain_body_ids(m: mujoco.MjModel, cmap: ChainMap) -> list[int]:
    """Bodies carrying the chain joints, in chain order (each once)."""
    chain = set(int(a) for a in cmap.chain_qpos_adr)
    return list(dict.fromkeys(int(m.jnt_bodyid[j]) for j in range(m.njnt) if int(m.jnt_qposadr[j]) in chain))


class Geometry:
    """The plant's recording geometry per control step (chain body poses, master base/elbow/tip, slave tip
    site): `live`, filled by the loop inside mj_step; else `finish` replays the qpos history."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, cmap: ChainMap, n: int, live: bool):
        self.m, self.cmap, self.live, self.ready = m, cmap, live, live
        self.bodies = np.asarray(chain_body_ids(m, cmap), dtype=np.int64)
        gids = np.array([m.jnt_bodyid[m.joint("master_elbow_joint").id], m.joint("master_shoulder_joint").id,
                         cmap.master_site_id, cmap.tip_site_id], dtype=np.int64)
        self.d = d if live else mujoco.MjData(m)
        self.inputs = (self.d.xpos, self.d.xquat, self.d.site_xpos, self.d.xanchor, self.bodies, gids)
        nb = len(self.bodies)
        self.body_pos, self.body_quat = np.zeros((n, nb, 3)), np.zeros((n, nb, 4))
        self.master_pos, self.tip = np.zeros((n, 3, 3)), np.zeros((n, 3))
        self.qpos_hist = np.zeros((0 if live else n, m.nq))
        self._none = (np.zeros((0, nb, 3)), np.zeros((0, nb, 4)), np.zeros((0, 3, 3)), np.zeros((0, 3)))
        self.base = np.asarray(cmap.octarm_base_pos, dtype=float)
        self.meta = {"master_base": tuple(float(v) for v in cmap.master_base_pos),
                     "slave_base": tuple(float(v) for v in self.base),
                     "body_half_size": body_half_sizes(m, self.bodies)}

    def outputs(self, k0: int, k1: int, replay: bool = False) -> tuple:
        """The recording arrays of steps k0..k1 for the loop (none without live geometry) or the replay."""
        if not (self.live or replay):
            return self._none
        return self.body_pos[k0:k1], self.body_quat[k0:k1], self.master_pos[k0:k1], self.tip[k0:k1]

    def fill(self, traj: Trajectory, k0: int, k1: int) -> None:
        """traj's plant geometry of steps k0..k1 (x2_plant (m, from the slave base), body poses, master
        points; once it exists) and the bases' meta."""
        traj.meta.update(self.meta)
        if self.ready:
            tip = self.tip[k0:k1]
            traj.x2_plant = np.stack([tip[:, 0] - self.base[0], tip[:, 2] - self.base[2]], axis=1)
            traj.body_pos, traj.body_quat = self.body_pos[k0:k1], self.body_quat[k0:k1]
            traj.master_pos = self.master_pos[k0:k1]

    def finish(self, traj: Trajectory, done: int, warned: dict[str, int], saturated: int) -> None:
        """The geometry of steps 0..done-1, the analytic backbone of the sensed q2 (world) and the meta."""
        m = self.m
        if not self.live:
            A.kinematics_replay(m._address, self.d._address, MJ_FUNCS, self.d.qpos, self.qpos_hist[:done],
                                self.inputs, self.outputs(0, done, replay=True))
        self.ready = True
        self.fill(traj, 0, done)
        bb = np.zeros((done, 3 * BACKBONE_POINTS + 1, 3))
        A.backbone_world(np.ascontiguousarray(traj.q2, dtype=float), BACKBONE_POINTS, self.base, bb)
        c = self.cmap
        traj.meta.update(segments=c.n_segments, actuation=c.actuation, enforce_cc=c.enforce_cc, backbone=bb,
                         body_names=[m.body(int(b)).name for b in self.bodies],
                         mujoco_warnings=int(sum(warned.values())), mujoco_warning_counts=warned)
        if c.actuation == "muscle":
            traj.meta["muscle_saturated_steps"] = saturated


def body_half_sizes(m: mujoco.MjModel, bodies: np.ndarray) -> np.ndarray:
    """(nb, 3) half extents (body frame, m) of a box for each body's first capsule (r, r, half length); a
    body without one gets a cube of the smallest capsule radius."""
    out = np.zeros((len(bodies), 3))
    radii = []
    for k, b in enumerate(bodies):
        gids = [g for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b] + m.body_geomnum[b]))
                if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE]
        if gids:
            r, h = (float(v) for v in m.geom_size[gids[0], :2])
            out[k] = (r, r, h)
            radii.append(r)
    r0 = min(radii) if radii else 0.01
    out[~out.any(axis=1)] = r0
    return out
