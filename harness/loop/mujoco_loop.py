"""Closed loop on the MuJoCo plant: the paper's law on the nominal models, one compiled kernel per chunk of
steps (`mujoco_kernels.mujoco_chunk`, calling MuJoCo's C `mj_step`).  Auto-reset is off: a bad state is
status 6 and any MuJoCo warning stops the run (7).  Recording geometry is copied after each step's first
mj_step (single-stage integrators) or replayed with `mj_kinematics` after the loop (RK4).  meta:
build_time, kernel_load_time, wall_time, geometry_time (s)."""

from __future__ import annotations

import time

import mujoco
import numpy as np

from controllers import master as master_model
from controllers.status import Status
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import ChunkRun, RunModel, compile_model, noise_table, progress_bar
from harness.loop.force_kernels import FORCE_MODES, filter_alpha
from harness.loop.mj_warnings import warning_counts
from harness.loop.native import MJ_FUNCS
from harness.loop.trajectory import ROW_WIDTH, Trajectory
from harness.plant.chain_map import ChainMap
from harness.plant.environment import N_POINTS, ContactMap
from harness.plant.mujoco_model import MujocoPlant

# control steps per compiled call (between progress, interrupt and warning checks; per live-view chunk)
MUJOCO_CHUNK = 1000
BACKBONE_POINTS = 8  # analytic backbone points per section in the recording
# integrators whose mj_step leaves the kinematics of the step's start state in MjData
LIVE_GEOMETRY_INTEGRATORS = ("euler", "implicit", "implicitfast")
FORCE_NOISE_STREAM = 1  # the force noise uses its own seeded stream: default_rng([seed, 1])


def plant_groups(scn: Scenario, m: mujoco.MjModel, d: mujoco.MjData, cmap: ChainMap,
                 contact: ContactMap | None, model: RunModel, n: int, rec: tuple) -> tuple:
    """The argument groups of `mujoco_kernels` for a run of n steps: mj, master, chain, sensing (contact
    points (n, N_POINTS, 6) or none), operator, rec = (qpos_hist, cmd_log (rows: [ctrl, qfrc] before each
    mj_step), geo_in, geo_out; off with 0 rows), act (nsat (1,): saturated muscle group-steps).  Applies
    the constant slave tip force F2 through d.xfrc_applied on the tip body."""
    fs, op, dt, s0 = scn.sensing.force, scn.operator, scn.control_dt, model.s0
    F = model.F.copy()
    if F[2] != 0.0 or F[3] != 0.0:
        tip = m.body("octarm_tip_body").id
        d.xfrc_applied[tip, 0] = F[2]
        d.xfrc_applied[tip, 2] = F[3]
    nc, servo = cmap.n_chain, scn.plant.actuation == "servo"
    kv_over_kp = (np.divide(cmap.servo_kv, cmap.servo_kp, out=np.zeros(nc), where=cmap.servo_kp > 0) if servo
                  else np.zeros(nc))
    c_act, muscle = cmap.chain_actuator_ids, (np.zeros(0), np.zeros(0))
    if cmap.muscle_actuator_ids.shape[0]:
        c_act = cmap.muscle_actuator_ids
        muscle = (np.asarray(cmap.muscle_radius, float), np.asarray(cmap.muscle_max_force, float))
    fnoise = np.zeros((1, 4))  # standard normals (n, 4) of the force sensor, when used
    if fs.mode == "sensed" and fs.noise_std > 0.0:
        fnoise = np.random.default_rng([scn.seed, FORCE_NOISE_STREAM]).standard_normal((n, 4))
    fdelay = int(round(fs.delay / dt))
    x0 = master_model.fk(scn.plant_master, s0[0:2])
    hand = np.array([x0[0], x0[1], 0.0, 0.0]) if op.enabled else np.zeros(4)
    mj = (m._address, d._address, MJ_FUNCS, scn.substeps, dt, d.ctrl, d.qfrc_applied,
          cmap.master_actuator_ids, c_act, d.warning.number)
    mpk_p = master_model.packed(scn.plant_master)
    master = (d.qpos, d.qvel, cmap.master_qpos_adr, cmap.master_dof_adr, mpk_p, np.zeros(2), np.zeros(2),
              np.zeros(2), np.zeros(2), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(2))
    chain = (cmap.chain_qpos_adr, cmap.chain_dof_adr, cmap.R, cmap.C, cmap.L0, cmap.elastic_args,
             np.empty(nc), np.empty(nc), np.empty(nc))
    sensing = (d.sensordata, contact.adr if contact is not None else np.zeros(0, dtype=np.int64),
               np.zeros((n if contact is not None else 0, N_POINTS, 6)), np.zeros((0, 6)), F,
               FORCE_MODES[fs.mode], fnoise, float(fs.noise_std), filter_alpha(fs.cutoff, dt), fdelay,
               np.zeros((fdelay + 1, 4)), np.zeros(4), np.zeros(2), np.zeros(4))
    operator = (bool(op.enabled), np.array([op.mass, op.stiffness, op.damping, op.grip_stiffness,
                                            op.grip_damping]),
                np.asarray(op.targets, dtype=float).reshape(-1, 3), hand, hand[:2].copy(), np.zeros(2))
    act = (servo, bool(scn.plant.servo_feedforward), dt, cmap.C, cmap.R, cmap.L0, kv_over_kp, muscle,
           np.concatenate([s0[4:10], s0[10:16]]), np.zeros(1, dtype=np.int64))
    return mj, master, chain, sensing, operator, rec, act


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
    tb = time.perf_counter()
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, d, cmap = make_plant(scn, plant, a.s0)
    build_time = time.perf_counter() - tb
    n, sub = scn.n_steps, scn.substeps
    if cmd_log is None:
        cmd_log = np.zeros((0, m.nu + m.nv))
    elif cmd_log.shape != (n * sub, m.nu + m.nv):
        raise ValueError(f"cmd_log must have shape {(n * sub, m.nu + m.nv)}, got {cmd_log.shape}")
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    geo = Geometry(m, d, cmap, n, live=scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS)
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    data = (np.zeros(16), noise, scale, rows, np.zeros((delay + 1, 2 + 2 * cmap.n_chain)), delay,
            scn.control_dt)
    groups = plant_groups(scn, m, d, cmap, plant.contact, a, n, (geo.qpos_hist, cmd_log, geo.inputs, geo.rec))
    warned: dict[str, int] = {}
    wnum = d.warning.number  # view of MuJoCo's warning counters

    def chunk(k: int, k1: int):
        status, mdone = A.mujoco_chunk(k, k1, a, data, groups)
        if wnum.any():
            warned.update(warning_counts(wnum))
            if status == 0:  # the kernel stops at the step that raised it; never pass silently
                status = Status.MUJOCO_WARNING
        return status, mdone

    tl = time.perf_counter()
    chunk(0, 0)  # no step: numba loads the kernel (on-disk cache) with the run's argument types
    load_time = time.perf_counter() - tl

    bar = progress_bar(progress, n, f"MuJoCo plant (N={cmap.n_segments}, {scn.plant.actuation})")
    run = ChunkRun(scn, rows, MUJOCO_CHUNK, bar, on_chunk, geo.fill)
    run.run(chunk)
    traj = run.trajectory(warned)
    cpts = groups[3][2]
    if cpts.shape[0]:
        traj.contact_points = cpts[:run.done].copy()
    tg = time.perf_counter()
    geo.finish(traj, run.done, warned, int(groups[6][9][0]))
    traj.meta.update(geometry_time=time.perf_counter() - tg, build_time=build_time,
                     kernel_load_time=load_time)
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
        self.out = (self.body_pos, self.body_quat, self.master_pos, self.tip)
        none = (np.zeros((0, nb, 3)), np.zeros((0, nb, 4)), np.zeros((0, 3, 3)), np.zeros((0, 3)))
        self.rec = self.out if live else none  # the loop's geo_out: filled inside mj_step when live
        self.base = np.asarray(cmap.octarm_base_pos, dtype=float)
        self.meta = {"master_base": tuple(float(v) for v in cmap.master_base_pos),
                     "slave_base": tuple(float(v) for v in self.base),
                     "body_half_size": body_half_sizes(m, self.bodies)}

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
                                self.inputs, self.out)
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
    for k, b in enumerate(bodies):
        gids = [g for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b] + m.body_geomnum[b]))
                if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE]
        if gids:
            r, h = (float(v) for v in m.geom_size[gids[0], :2])
            out[k] = (r, r, h)
    found = out.any(axis=1)
    out[~found] = out[found, 0].min() if found.any() else 0.01
    return out
