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

import os
import threading
import time

import mujoco
import numpy as np

from harness.config.runtime import overlap_setting
from harness.config.scenario import Scenario
from harness.loop.aot import A
from harness.loop.common import (
    STOP,
    common_arrays,
    initial_state,
    noise_table,
    progress_bar,
    run_meta,
    set_outcome,
)
from harness.loop.fast import jit_wanted
from harness.loop.force_args import ForceArgs
from harness.loop.mj_warnings import WarningSink
from harness.loop.native import MJ_FUNCS, SYNC_GO, SYNC_LAST, SYNC_S1, SYNC_S2, SYNC_SIZE, SYNC_STOP
from harness.loop.trajectory import ROW_WIDTH, Trajectory
from harness.plant.chain_map import ChainMap
from harness.plant.mujoco_model import MujocoPlant

# Control steps per compiled call between progress/interrupt/warning checks: the first call, and every
# call when `on_chunk` is given (a live view).  1000 steps are 50-100 ms at N = 8.
MUJOCO_CHUNK = 1000
# Later calls, without on_chunk, last about CHUNK_SECONDS (the steps per second of the previous call): the
# progress bar and Ctrl-C still answer within ~0.25 s, and there are 4-6 calls in the paper run instead of
# 20.  Each return from a call needs the GIL back; while `harness.output.prefetch` imports Rerun and
# matplotlib beside the loop, that wait was 0.10-0.15 s of the paper run's loop (README, End to end).
# The numbers do not depend on where the calls split the run
# (tests/test_speed_paths.py::test_chunk_boundaries_do_not_change_the_run).
CHUNK_SECONDS = 0.25


# By default (overlap_plan's AUTO, AFTER_BESIDE) the loop's thread steps MuJoCo in calls of PROBE_CALL steps
# (MUJOCO_CHUNK while work runs beside, or with on_chunk) until the physics thread may start and at least 2
# calls after the first (which starts cold) are timed.  The thread's first call has PROBE_CHUNKS times as
# many steps (MUJOCO_CHUNK with on_chunk); the thread goes on unless that call took more than PROBE_MARGIN
# times the time per step of the serial calls (the median of the last 3).
PROBE_CALL = 100
PROBE_CHUNKS = 2
PROBE_MARGIN = 1.05


def next_chunk(steps: int, seconds: float, on_chunk: bool) -> int:
    """Control steps for the next compiled call, after a call of `steps` steps that took `seconds`."""
    if on_chunk or steps <= 0 or seconds <= 0.0:
        return MUJOCO_CHUNK
    return max(MUJOCO_CHUNK, int(steps * CHUNK_SECONDS / seconds))


WARNINGS = [w for name, w in mujoco.mjtWarning.__members__.items() if name != "mjNWARNING"]


def warning_counts(numbers: np.ndarray) -> dict[str, int]:
    """Non-zero MuJoCo warning counters by name, from the counters (mjData.warning.number, or the copy the
    physics thread keeps)."""
    out = {}
    for name, w in mujoco.mjtWarning.__members__.items():
        if name == "mjNWARNING":
            continue
        n = int(numbers[int(w)])
        if n:
            out[name] = n
    return out


def make_plant(scn: Scenario, plant: MujocoPlant | None = None
               ) -> tuple[mujoco.MjModel, mujoco.MjData, ChainMap]:
    """Compiled plant model, data at the scenario's initial state, and its ChainMap.
    plant: an already built `MujocoPlant` of this scenario (default: built here)."""
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, cmap = plant.model, plant.cmap
    m.opt.timestep = scn.plant.physics_dt
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    d = mujoco.MjData(m)
    s0 = initial_state(scn)
    d.qpos[cmap.master_qpos_adr] = s0[0:2]
    d.qvel[cmap.master_dof_adr] = s0[2:4]
    cmap.set_q2(d, s0[4:10], s0[10:16])
    mujoco.mj_forward(m, d)
    return m, d, cmap


def simulate_mujoco(scn: Scenario, progress: bool = False, cmd_log: np.ndarray | None = None,
                    plant: MujocoPlant | None = None, on_chunk=None, on_running=None,
                    overlap: bool | None = None) -> Trajectory:
    """Run the scenario on the MuJoCo plant; returns the Trajectory (possibly cut short).

    cmd_log: optional (n_steps * substeps, nu + nv) array that receives, for every mj_step, the
    [ctrl, qfrc_applied] applied before it (to replay the same physics with raw mj_step).
    on_chunk: optional callable receiving each finished chunk of steps as a `Trajectory` (with the plant
    geometry when the integrator provides it in the loop, see `_chunk`).  on_running: called once when
    the kernel is loaded, before the first step (`harness.loop.simulate`): from then on only the compiled
    loop runs, releasing the GIL ~0.25 s at a time.
    overlap: step MuJoCo in a second thread, in its two phases (`harness.loop.native.physics_server`): the
    first (mj_step1: positions, velocities) of each state runs while this thread computes the control step
    from it; the same numbers as mj_step.  True: from the first step; False: never; None =
    `overlap_plan(scn, beside=on_running is not None)`: where a core is free, this thread steps MuJoCo in
    short calls until the physics thread may start (after three calls, or, with 2 CPUs and work beside the
    loop, once that work has ended: on_running returns its thread); the thread's first call is compared
    with the serial ones (PROBE_CALL, PROBE_MARGIN), and it goes on only if it is not slower.
    True for an integrator MuJoCo cannot split (RK4) raises ValueError; interpreted kernels
    (TELEOP_NO_JIT=1) always run serially.  traj.meta["overlap_from_step"]: the control step from which
    the physics thread stepped MuJoCo (None: never), "overlap_steps": how many steps it stepped."""
    if overlap is None:
        plan = overlap_plan(scn, beside=on_running is not None)
    elif overlap and not jit_wanted():  # the kernels in Python: two threads would take turns on the GIL
        plan = SERIAL
    elif overlap and not two_phase_ok(scn):
        raise ValueError(f"overlap=True: MuJoCo's two-phase step needs one of the integrators "
                         f"{', '.join(LIVE_GEOMETRY_INTEGRATORS)} (its mj_step2 integrates RK4 with Euler); "
                         f"plant.integrator = {scn.plant.integrator!r}")
    else:
        plan = THREADED if overlap else SERIAL
    tb = time.perf_counter()
    if plant is None:
        plant = MujocoPlant.build(scn)
    m, d, cmap = make_plant(scn, plant)
    build_time = time.perf_counter() - tb
    n = scn.n_steps
    sub = scn.substeps
    if cmd_log is None:
        cmd_log = np.zeros((0, m.nu + m.nv))
    elif cmd_log.shape != (n * sub, m.nu + m.nv):
        raise ValueError(f"cmd_log must have shape {(n * sub, m.nu + m.nv)}, got {cmd_log.shape}")
    log = cmd_log.shape[0] > 0
    a = common_arrays(scn)
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    geo = _Geometry(m, d, cmap, n, live=scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS)
    servo = scn.plant.actuation == "servo"
    nchain = cmap.n_chain
    kv_over_kp = (np.divide(cmap.servo_kv, cmap.servo_kp, out=np.zeros(nchain), where=cmap.servo_kp > 0)
                  if servo else np.zeros(nchain))
    s0 = initial_state(scn)
    ref = np.concatenate([s0[4:10], s0[10:16]])  # servo reference [q_ref, dq_ref]
    delay = int(round(scn.plant.actuation_delay / scn.control_dt))
    cmdbuf = np.zeros((delay + 1, 2 + 2 * nchain))
    force = ForceArgs(scn, m, d, cmap, plant.contact, n, s0, a["F"])
    bar = progress_bar(progress, n, f"MuJoCo plant (N={cmap.n_segments}, {scn.plant.actuation})")
    status, done, k = 0, 0, 0
    interrupted = False
    warned: dict[str, int] = {}
    sink = WarningSink()  # MuJoCo's warning text raised by this run's threads
    st = _Stepping(m, d, sub, n * sub, geo, force, sink)

    def chunk(k: int, k1: int):
        return A.mujoco_chunk(
            m._address, d._address, MJ_FUNCS, k, k1, sub, scn.control_dt, d.qpos, d.qvel, d.ctrl,
            d.qfrc_applied, cmap.master_qpos_adr, cmap.master_dof_adr, cmap.master_actuator_ids,
            cmap.chain_qpos_adr, cmap.chain_dof_adr, cmap.chain_actuator_ids, cmap.R, cmap.C, cmap.L0,
            cmap.elastic_args, servo, scn.plant.servo_feedforward, kv_over_kp, a["traj"], noise,
            scale, a["F"], a["mpk_c"], a["spk_c"], a["nodes"], a["weights"], a["gains"], a["spec"],
            ref, cmdbuf, delay, rows[k:k1], geo.qpos_hist[k:k1],
            cmd_log[k * sub:k1 * sub] if log else cmd_log, geo.inputs, geo.outputs(k, k1), st.wseen,
            force.args(k, k1), st.sync)

    tl = time.perf_counter()
    chunk(0, 0)  # no step: numba loads the kernel (on-disk cache) with the run's argument types
    load_time = time.perf_counter() - tl
    beside = None
    serial_rates: list[float] = []  # seconds per step of the full serial calls after the first (probing)
    try:
        if plan == THREADED:
            st.start(0)
        t0 = time.perf_counter()  # the loop's wall time: after the kernel load and the physics thread's start
        if on_running is not None:  # the kernel is loaded: nothing but the compiled loop runs from here
            beside = on_running()
        if plan == AFTER_BESIDE and not callable(getattr(beside, "is_alive", None)):
            plan = SERIAL  # no handle on the work beside: a core may never be free
        probing = plan in (AUTO, AFTER_BESIDE)
        ref_size = MUJOCO_CHUNK if on_chunk is not None or plan == AFTER_BESIDE else PROBE_CALL
        size = ref_size if probing else MUJOCO_CHUNK
        while k < n:
            if (probing and not st.threaded and len(serial_rates) >= 2
                    and (plan == AUTO or not beside.is_alive())):  # a core is free: the physics thread's turn
                st.start(k)
                size = MUJOCO_CHUNK if on_chunk is not None else PROBE_CHUNKS * ref_size
            k1 = min(n, k + size)
            tc = time.perf_counter()
            status, mdone = chunk(k, k1)
            spent = time.perf_counter() - tc
            st.count(mdone)
            if probing and mdone == k1 - k:
                if st.threaded:  # the thread's first call decides
                    if spent / mdone > PROBE_MARGIN * float(np.median(serial_rates[-3:])):
                        st.stop()  # slower than this thread alone (a busy machine): it steps MuJoCo again
                    probing = False
                elif k > 0 and mdone == ref_size:  # a reference (the first call starts cold)
                    serial_rates.append(spent / mdone)
            size = ref_size if probing and not st.threaded else next_chunk(mdone, spent, on_chunk is not None)
            done = k + mdone
            if bar is not None:
                bar.update(mdone)
            if on_chunk is not None and mdone:
                on_chunk(_chunk(scn, m, cmap, geo, rows, k, done))
            if st.wseen.any():
                warned = warning_counts(st.wseen)
                if status == 0:  # the kernel stops at the step that raised it; never pass silently
                    status = 7
            if status != 0:
                break
            k = k1
            if STOP.is_set():
                interrupted = True
                break
    finally:
        st.stop()
        sink.close()
        if bar is not None:
            bar.close()
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
    traj.meta["overlap"] = st.from_step is not None
    traj.meta["overlap_from_step"] = st.from_step
    traj.meta["overlap_steps"] = st.threaded_steps
    traj.meta["mujoco_warnings"] = int(sum(warned.values()))
    traj.meta["mujoco_warning_counts"] = warned
    captured = sink.text
    if st.from_step is not None:
        # MuJoCo says each kind of warning once: a kind first raised after the last step is dropped, and one
        # raised by the physics thread's mj_step1 of a state that this thread then stepped is said twice
        captured = list(dict.fromkeys(captured))[:len(warned)]
    traj.meta["mujoco_warning_text"] = captured[:20]
    detail = ""
    if warned:
        detail = " (" + ", ".join(f"{k_}: {v}" for k_, v in warned.items()) + ")"
        if captured:
            detail += f"; MuJoCo says: {captured[0].strip()}"
    set_outcome(traj, status, interrupted, detail=detail)
    return traj


def two_phase_ok(scn: Scenario) -> bool:
    """Whether MuJoCo's mj_step1 + mj_step2 give mj_step's numbers for this plant: the single-stage
    integrators (MuJoCo's mj_step2 integrates RK4 with Euler)."""
    return scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS


SERIAL, THREADED, AUTO, AFTER_BESIDE = "serial", "threaded", "auto", "after_beside"  # overlap_plan's answers


def overlap_plan(scn: Scenario, beside: bool = False) -> str:
    """Who steps MuJoCo in `simulate_mujoco(overlap=None)`: the loop's thread throughout (SERIAL), or, where
    MuJoCo allows the split (`two_phase_ok`), the kernels are compiled and a core is free, the physics thread
    after a comparison (`simulate_mujoco`): AUTO when this process may run on at least 2 CPUs, 3 when other
    work runs beside the loop (`beside`: the output imports of `teleop run`); AFTER_BESIDE with 2 CPUs and
    work beside: not before that work has ended.  The thread trades CPU for time (each thread spin-waits for
    the other: 1.4-1.9x the CPU of a serial run, benchmarks/bench_threads.py): worth it only on an idle core.
    TELEOP_OVERLAP=1 / 0 forces it on from the first step (THREADED) / off (SERIAL), where MuJoCo allows
    it."""
    if not two_phase_ok(scn) or not jit_wanted():
        return SERIAL
    forced = overlap_setting()  # TELEOP_OVERLAP (ConfigError if it is not 0 or 1)
    if forced is not None:
        return THREADED if forced else SERIAL
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    if cpus >= (3 if beside else 2):
        return AUTO
    return AFTER_BESIDE if cpus >= 2 else SERIAL


class _Stepping:
    """Who steps MuJoCo in a run: this thread (mj_step; `sync` empty) or the physics thread (`start`, `stop`:
    between two compiled calls, at any step; the numbers do not change, tests/test_overlap.py).
    wseen: the warning counters the kernel checks after each step: MuJoCo's own, or the physics thread's copy
    after each mj_step2 (an mj_step1 of a state the loop then does not step must not count); the loop reads
    the sensors from force.sensordata: d.sensordata, or that thread's copy (mj_step1 rewrites them)."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, substeps: int, last: int, geo: _Geometry,
                 force: ForceArgs, sink: WarningSink):
        self.m, self.d, self.substeps, self.last = m, d, substeps, last
        self.geo, self.force, self.sink = geo, force, sink
        self.wnum = d.warning.number  # view of MuJoCo's warning counters
        self.wseen = self.wnum
        self.sync = np.zeros(0, dtype=np.int64)
        self.helper: threading.Thread | None = None
        self.from_step: int | None = None
        self.threaded_steps = 0

    @property
    def threaded(self) -> bool:
        return self.helper is not None

    def start(self, k: int) -> None:
        """The physics thread steps MuJoCo from control step k on (the state MjData holds)."""
        if self.helper is not None:
            return
        self.force.sensordata = self.d.sensordata.copy()
        self.wseen = self.wnum.copy()
        self.sync = np.zeros(SYNC_SIZE, dtype=np.int64)
        self.helper = _start_helper(self.m, self.d, self.sync, self.last, self.wnum, self.wseen,
                                    self.force.sensordata, self.substeps, self.geo, k * self.substeps)
        self.sink.follow(self.helper)
        if self.from_step is None:
            self.from_step = k

    def stop(self) -> None:
        """This thread steps MuJoCo again: the physics thread ends, and MjData's sensors and warning counters
        are those of its last mj_step2 (its mj_step1 of the next state is redone by mj_step)."""
        if self.helper is None:
            return
        self.sync[SYNC_GO] = SYNC_STOP
        self.helper.join()
        self.helper = None
        self.d.sensordata[:] = self.force.sensordata
        self.wnum[:] = self.wseen
        self.force.sensordata = self.d.sensordata
        self.wseen = self.wnum
        self.sync = np.zeros(0, dtype=np.int64)

    def count(self, steps: int) -> None:
        if self.helper is not None:
            self.threaded_steps += steps


def _start_helper(m: mujoco.MjModel, d: mujoco.MjData, sync: np.ndarray, last: int, wnum: np.ndarray,
                  wsnap: np.ndarray, sens_snap: np.ndarray, substeps: int,
                  geo: _Geometry, g0: int) -> threading.Thread:
    """Start the thread that steps MuJoCo for `mujoco_chunk` (`harness.loop.native.physics_server`) from
    physics step g0 (the state MjData holds).  The kernel is first called with the stop flag set (returns
    at once): it is loaded, or built, here."""
    sync[SYNC_GO] = SYNC_STOP
    args = (m._address, d._address, MJ_FUNCS, sync, wnum, wsnap, d.sensordata, sens_snap, substeps,
            geo.inputs, geo.outputs(0, geo.tip.shape[0]))
    A.physics_server(*args)
    sync[:] = 0
    sync[SYNC_GO] = g0
    sync[SYNC_S2] = g0
    sync[SYNC_S1] = -2  # no mj_step1 done yet
    sync[SYNC_LAST] = last
    t = threading.Thread(target=A.physics_server, args=args,
                         name="mujoco-physics", daemon=True)
    t.start()
    return t


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
