"""Closed loop on the MuJoCo plant.

The controllers run on the nominal analytic models (Scenario.master/slave); MuJoCo simulates the
plant built from Scenario.plant (its own parameters, segments, actuation).  The per-step work is
one compiled kernel (`harness.loop.mujoco_kernels.mujoco_chunk`) that also calls MuJoCo's C `mj_step`, so no
Python runs per step.  MuJoCo's auto-reset on instability is disabled: bad accelerations leave NaN or
exploding states that the kernel detects, and every MuJoCo warning is counted and reported.

Recording geometry (MuJoCo tip site x2_plant, slave segment body poses, master base/elbow/tip): with
the single-stage integrators, mj_step leaves the kinematics of the step's start state in MjData, so the
loop copies those rows after the first mj_step of each control step (no extra work); with RK4 the loop
keeps the qpos history and MuJoCo's C `mj_kinematics` is replayed afterwards from compiled code
(`harness.loop.mujoco_kernels.kinematics_replay`).  The analytic backbone of the sensed q2 is computed after
the loop by a compiled loop.  Both give the numbers of a per-step Python `mujoco.mj_kinematics` replay
bit for bit (tests/test_speed_paths.py).

Timings in traj.meta: "build_time" (plant model build + initial state), "kernel_load_time" (numba
loading the compiled loop, in a fresh process mostly numba's own initialisation), "wall_time" (the
control loop), "geometry_time" (the geometry/backbone work after the loop).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np

from controllers.status import Status
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import (
    ChunkRun,
    RunModel,
    compile_model,
    noise_table,
    progress_bar,
    run_meta,
    set_outcome,
)
from harness.loop.force_args import ForceArgs
from harness.loop.mj_warnings import WarningSink
from harness.loop.native import MJ_FUNCS
from harness.loop.trajectory import ROW_WIDTH, Trajectory
from harness.plant.chain_map import ChainMap
from harness.plant.mujoco_model import MujocoPlant

# Control steps per compiled call between progress, interrupt and warning checks (and per live-view chunk):
# 1000 steps are 50-100 ms at N = 8.  The numbers do not depend on where the calls split the run
# (tests/test_speed_paths.py::test_chunk_boundaries_do_not_change_the_run).
MUJOCO_CHUNK = 1000


WARNINGS = [w for name, w in mujoco.mjtWarning.__members__.items() if name != "mjNWARNING"]


def warning_counts(numbers: np.ndarray) -> dict[str, int]:
    """Non-zero MuJoCo warning counters by name, from the counters (mjData.warning.number)."""
    out = {}
    for name, w in mujoco.mjtWarning.__members__.items():
        if name == "mjNWARNING":
            continue
        n = int(numbers[int(w)])
        if n:
            out[name] = n
    return out


def muscle_args(cmap: ChainMap) -> tuple[np.ndarray, np.ndarray]:
    """(radius (3,), max_force (3,)) of the muscle groups under muscle actuation, else two empty arrays
    (`harness.loop.mujoco_kernels.chain_commands`)."""
    if cmap.muscle_actuator_ids.shape[0]:
        return np.asarray(cmap.muscle_radius, float), np.asarray(cmap.muscle_max_force, float)
    return np.zeros(0), np.zeros(0)


def chain_ctrl_ids(cmap: ChainMap) -> np.ndarray:
    """The chain's actuators, in the order of the chain part of the command vector: the muscle groups
    under muscle actuation, else one servo or motor per chain joint."""
    return cmap.muscle_actuator_ids if cmap.muscle_actuator_ids.shape[0] else cmap.chain_actuator_ids


def make_plant(scn: Scenario, plant: MujocoPlant | None = None, s0: np.ndarray | None = None
               ) -> tuple[mujoco.MjModel, mujoco.MjData, ChainMap]:
    """Compiled plant model, data at the scenario's initial state s0 (16,) (default: computed here), and its
    ChainMap.  plant: an already built `MujocoPlant` of this scenario (default: built here)."""
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
    """Run the scenario on the MuJoCo plant; returns the Trajectory (possibly cut short).

    cmd_log: optional (n_steps * substeps, nu + nv) array that receives, for every mj_step, the
    [ctrl, qfrc_applied] applied before it (to replay the same physics with raw mj_step).
    on_chunk: optional callable receiving each finished chunk of steps as a `Trajectory` (with the plant
    geometry when the integrator provides it in the loop, see `_chunk`).  model: the scenario's `RunModel`
    (default: compiled here)."""
    a = model if model is not None else compile_model(scn)
    s0 = a.s0
    tb = time.perf_counter()
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, d, cmap = make_plant(scn, plant, s0)
    build_time = time.perf_counter() - tb
    n = scn.n_steps
    sub = scn.substeps
    if cmd_log is None:
        cmd_log = np.zeros((0, m.nu + m.nv))
    elif cmd_log.shape != (n * sub, m.nu + m.nv):
        raise ValueError(f"cmd_log must have shape {(n * sub, m.nu + m.nv)}, got {cmd_log.shape}")
    log = cmd_log.shape[0] > 0
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    geo = _Geometry(m, d, cmap, n, live=scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS)
    servo = scn.plant.actuation == "servo"
    nchain = cmap.n_chain
    kv_over_kp = (np.divide(cmap.servo_kv, cmap.servo_kp, out=np.zeros(nchain), where=cmap.servo_kp > 0)
                  if servo else np.zeros(nchain))
    ref = np.concatenate([s0[4:10], s0[10:16]])  # servo reference [q_ref, dq_ref]
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 2 + 2 * nchain))
    force = ForceArgs(scn, m, d, cmap, plant.contact, n, s0, a.F)
    bar = progress_bar(progress, n, f"MuJoCo plant (N={cmap.n_segments}, {scn.plant.actuation})")
    warned: dict[str, int] = {}
    wnum = d.warning.number  # view of MuJoCo's warning counters

    muscle = muscle_args(cmap)
    nsat = np.zeros(1, dtype=np.int64)  # saturated muscle group-steps of the run
    plant_args = (m._address, d._address, MJ_FUNCS, sub, scn.control_dt, cmap.master_qpos_adr,
                  cmap.master_dof_adr, cmap.master_actuator_ids, cmap.chain_qpos_adr, cmap.chain_dof_adr,
                  chain_ctrl_ids(cmap), cmap.R, cmap.C, cmap.L0, cmap.elastic_args, servo,
                  scn.plant.servo_feedforward, kv_over_kp, muscle)

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
        on_chunk(_chunk(scn, m, cmap, geo, rows, k, done))

    run = ChunkRun(n, MUJOCO_CHUNK, bar, part if on_chunk is not None else None)
    with WarningSink() as sink:  # MuJoCo's warning text raised by this run
        try:
            t0 = time.perf_counter()
            run.run(chunk)
        finally:
            if bar is not None:
                bar.close()
    status, done, interrupted = run.status, run.done, run.interrupted
    wall = time.perf_counter() - t0
    traj = Trajectory.from_rows(rows[:done])
    if force.cpts.shape[0]:
        traj.contact_points = force.cpts[:done].copy()
    meta = run_meta(scn, wall)
    traj.meta.update(meta)
    tg = time.perf_counter()
    traj.meta.update(_plant_geometry(m, cmap, geo, done, traj))
    traj.meta["geometry_time"] = time.perf_counter() - tg
    traj.meta["build_time"] = build_time
    traj.meta["kernel_load_time"] = load_time
    traj.meta["mujoco_warnings"] = int(sum(warned.values()))
    if scn.plant.actuation == "muscle":
        traj.meta["muscle_saturated_steps"] = int(nsat[0])
    traj.meta["mujoco_warning_counts"] = warned
    captured = sink.text
    traj.meta["mujoco_warning_text"] = captured[:20]
    detail = ""
    if warned:
        detail = " (" + ", ".join(f"{k_}: {v}" for k_, v in warned.items()) + ")"
        if captured:
            detail += f"; MuJoCo says: {captured[0].strip()}"
    set_outcome(traj, status, interrupted, detail=detail)
    return traj


def _chunk(scn: Scenario, m: mujoco.MjModel, cmap: ChainMap, geo: _Geometry, rows: np.ndarray, k0: int,
           k1: int) -> Trajectory:
    """Steps k0..k1 as a Trajectory for live viewing: the plant geometry of the loop (single-stage
    integrators; with RK4 it exists only after the run, and the chunk carries the analytic state only)."""
    part = Trajectory.from_rows(rows[k0:k1])
    part.meta.update(run_meta(scn, 0.0))
    base = np.asarray(cmap.octarm_base_pos, dtype=float)
    part.meta.update(master_base=tuple(float(v) for v in cmap.master_base_pos),
                     slave_base=tuple(float(v) for v in base), body_half_size=body_half_sizes(m, geo.bodies))
    if geo.live:
        tip = geo.tip[k0:k1]
        part.x2_plant = np.stack([tip[:, 0] - base[0], tip[:, 2] - base[2]], axis=1)
        part.body_pos, part.body_quat = geo.body_pos[k0:k1].copy(), geo.body_quat[k0:k1].copy()
        part.master_pos = geo.master_pos[k0:k1].copy()
    return part


BACKBONE_POINTS = 8  # analytic backbone points per section in the recording
# Integrators whose mj_step leaves the kinematics of the step's start state in MjData (one stage):
# the loop copies the recording geometry from there; others (RK4) replay mj_kinematics afterwards.
LIVE_GEOMETRY_INTEGRATORS = ("euler", "implicit", "implicitfast")


def chain_body_ids(m: mujoco.MjModel, cmap: ChainMap) -> list[int]:
    """Bodies carrying the chain joints, in chain order (each once)."""
    chain = set(int(a) for a in cmap.chain_qpos_adr)
    return list(dict.fromkeys(int(m.jnt_bodyid[j]) for j in range(m.njnt) if int(m.jnt_qposadr[j]) in chain))


class _Geometry:
    """Recording geometry of the plant per control step: chain body poses, master base/elbow/tip,
    slave tip site.  `live`: filled by the loop from the kinematics inside mj_step; else the loop
    keeps the qpos history and `finish` replays MuJoCo's C mj_kinematics (compiled)."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, cmap: ChainMap, n: int, live: bool):
        self.live = live
        self.bodies = np.asarray(chain_body_ids(m, cmap), dtype=np.int64)
        gids = np.array([m.jnt_bodyid[m.joint("master_elbow_joint").id], m.joint("master_shoulder_joint").id,
                         cmap.master_site_id, cmap.tip_site_id], dtype=np.int64)
        self.d = d if live else mujoco.MjData(m)
        self.inputs = (self.d.xpos, self.d.xquat, self.d.site_xpos, self.d.xanchor, self.bodies, gids)
        nb = len(self.bodies)
        self.body_pos = np.zeros((n, nb, 3))
        self.body_quat = np.zeros((n, nb, 4))
        self.master_pos = np.zeros((n, 3, 3))
        self.tip = np.zeros((n, 3))
        self.qpos_hist = np.zeros((0 if live else n, m.nq))
        self._none = (np.zeros((0, nb, 3)), np.zeros((0, nb, 4)), np.zeros((0, 3, 3)), np.zeros((0, 3)))

    def outputs(self, k0: int, k1: int) -> tuple:
        if not self.live:
            return self._none
        return self.body_pos[k0:k1], self.body_quat[k0:k1], self.master_pos[k0:k1], self.tip[k0:k1]

    def finish(self, m: mujoco.MjModel, done: int) -> None:
        if not self.live:
            A.kinematics_replay(m._address, self.d._address, MJ_FUNCS, self.d.qpos, self.qpos_hist[:done],
                                self.inputs, self.outputs_all(done))

    def outputs_all(self, done: int) -> tuple:
        return self.body_pos[:done], self.body_quat[:done], self.master_pos[:done], self.tip[:done]


def _plant_geometry(m: mujoco.MjModel, cmap: ChainMap, geo: _Geometry, done: int, traj: Trajectory) -> dict:
    """MuJoCo tip site (x2_plant), slave body poses, master joint positions (from the loop or a compiled
    mj_kinematics replay) and the analytic backbone of the sensed q2 (compiled loop)."""
    geo.finish(m, done)
    body_pos, body_quat, master_pos, tip = geo.outputs_all(done)
    base = np.asarray(cmap.octarm_base_pos, dtype=float)
    traj.x2_plant = np.stack([tip[:, 0] - base[0], tip[:, 2] - base[2]], axis=1)
    traj.body_pos = body_pos
    traj.body_quat = body_quat
    traj.master_pos = master_pos
    # analytic backbone of the sensed q2, in world coordinates (for the overlay)
    bb = np.zeros((done, 3 * BACKBONE_POINTS + 1, 3))
    A.backbone_world(np.ascontiguousarray(traj.q2, dtype=float), BACKBONE_POINTS, base, bb)
    return {
        "master_base": tuple(float(v) for v in cmap.master_base_pos),
        "slave_base": tuple(float(v) for v in base),
        "segments": cmap.n_segments, "actuation": cmap.actuation, "enforce_cc": cmap.enforce_cc,
        "body_names": [m.body(int(b)).name for b in geo.bodies], "backbone": bb,
        "body_half_size": body_half_sizes(m, geo.bodies),
    }


def body_half_sizes(m: mujoco.MjModel, bodies: np.ndarray) -> np.ndarray:
    """(nb, 3) half extents (x, y, z in the body frame, m) of a box standing for each body's first
    capsule geom (the segment rod: radius, radius, half the rod length, so consecutive boxes tile the
    chain); a body without one (the tip body) gets a cube of the smallest capsule radius."""
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
