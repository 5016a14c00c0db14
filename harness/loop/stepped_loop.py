"""The one Python-level closed loop: any controller on any plant stepped from Python (protocol
`harness.plant.stepped.SteppedPlant`).

Plants: the Cosserat rod (`harness.plant.cosserat_plant`) and the Python-stepped adapters of the MuJoCo
and analytic plants (`harness.loop.stepped_plants`).  Controllers: any `controllers.interface.Controller`
(through `harness.loop.interface_adapter.InterfaceController`); the paper's law under its registered
name "paper" takes its compiled fast path (one compiled call per step,
`harness.loop.stepped_kernels.stepped_paper_step`).  The paper's law on the MuJoCo / analytic plants
runs in the compiled loops instead (`harness.loop.simulate`).
The loop over control steps is Python, and each step is a few compiled calls.  Per control step k
(t = k control_dt):

    status = plant.true_state(state)            noise-free [q1, dq1, q2, dq2] (16,); plant checks
    x_d(t), eq. (40)                            K.desired
    sensed = state + AWGN                       K.add_noise, the seeded table of noise_table (as the
                                                other loops: same seed -> same noise)
    action = controller.step(observation)       T1, T2, u2, deN (and a servo reference); "paper": the
                                                compiled laws (12)-(13), (17)-(33) (as the compiled loops)
    record row of the true state                K.record_row (ROW layout of harness.loop.trajectory)
    servo reference                             dq2_ref += u2 dt, q2_ref += dq2_ref dt (semi-implicit
                                                Euler, as harness.loop.mujoco_kernels.mujoco_commands),
                                                or the controller's own (Action.use_ref)
    plant.command(T1, T2, q2_ref, dq2_ref, q2s) through a ring buffer of plant.actuation_delay; q2s
                                                the sensed q2 of the commanding step (MuJoCo torque map)
    status = plant.advance(control_dt)

Statuses are those of `controllers.status.Status` (1 non-finite command, 2/3 singular, 4
runaway, 5 section length <= 0, 8 non-finite or exploding plant state, ...); the run stops at the
first non-zero one, keeps every recorded row and says why (`set_outcome`).  `harness.loop.common.STOP`
interrupts between steps.  Per-step buffers are preallocated; the glue around the plant and the
controller (state checks, sensed force, record columns, command checks, servo reference, delay ring) is
two compiled calls (`harness.loop.stepped_kernels`); a plant with `record(k)` / `finish(traj, done)` (the
Cosserat rod, the MuJoCo adapter) keeps its own recording, otherwise the plant geometry is copied into
(n, ...) arrays (`plant.geometry()` returns the same arrays every call).
"""

from __future__ import annotations

import time

import numpy as np

from controllers.control import MASTER_INFO, SLAVE_INFO
from harness.config.scenario import Scenario
from harness.loop.common import (
    CHUNK,
    STOP,
    RunModel,
    compile_model,
    noise_table,
    progress_bar,
    run_meta,
    set_outcome,
)
from harness.loop.fast import K
from harness.loop.interface_adapter import ControllerFailure, InterfaceController, is_compiled
from harness.loop.trajectory import ROW_SLICES, ROW_WIDTH, Trajectory
from harness.plant.stepped import SteppedPlant

EXPLODING = 1e6  # |state| above this is a diverged plant (status 8)


def simulate_stepped(scn: Scenario, plant: SteppedPlant, progress: bool = False,
                     on_chunk=None, model: RunModel | None = None) -> Trajectory:
    """Run the scenario on a stepped plant; returns the Trajectory (possibly cut short).
    The controller is the scenario's (`scn.controller`); model: the scenario's `RunModel` (default: compiled
    here).
    on_chunk: optional callable receiving every CHUNK steps as a `Trajectory` (time series only).

    traj.x2_plant: the plant's own slave tip (n, 2); traj.master_pos: (n, 3, 3) if the plant's
    geometry has "master"; every other geometry array goes to traj.meta["geometry"][name] (n, ...).
    A plant with `record(k)` / `finish(traj, done)` (the MuJoCo adapter, the Cosserat rod) records its own
    geometry instead.
    Timings: meta "build_time" (controller and plant reset), "wall_time" (the loop)."""
    tb = time.perf_counter()
    n = scn.n_steps
    dt = scn.control_dt
    model = model if model is not None else compile_model(scn)
    s0 = model.s0
    fast = is_compiled(scn)  # the paper's law: its compiled one-call step
    ctrl = None if fast else InterfaceController(scn, model)
    cname = scn.controller.name
    error, failed = "", False
    plant.reset(s0)
    if hasattr(plant, "stop"):  # a plant with long inner loops (the rod) checks the stop flag itself
        plant.stop = STOP
    if ctrl is not None:
        try:
            ctrl.reset(model)
        except ControllerFailure as exc:
            error, failed, n = str(exc), True, 0
    build_time = time.perf_counter() - tb
    noise, scale = noise_table(scn, scn.n_steps)
    a = model
    traj_p, mpk, gains, spec = a.traj, a.mpk_c, a.gains, a.spec
    rows = np.zeros((n, ROW_WIDTH))
    own_geo = hasattr(plant, "finish")
    tips = np.zeros((0 if own_geo else n, 2))
    geo = {} if own_geo else {name: np.zeros((n, *np.shape(v))) for name, v in plant.geometry().items()}
    state, sensed = np.zeros(16), np.zeros(16)
    # interaction forces: a plant with `forces(F (4,), contact (5,))` (the Cosserat plant's contact) gives
    # the true tip forces each step, else the constant ones; the paper controller (its `F`) gets them in
    # `exact` sensing mode, zeros in `ignored` ("sensed" needs the MuJoCo plant: config check)
    plant_forces = getattr(plant, "forces", None)
    Ftrue, cinfo = a.F.copy(), np.zeros(5)
    ignored = scn.sensing.force.mode == "ignored"
    # every controller reads the sensed F (F_true, or zeros when ignored), written by the check kernel each
    # step: the paper's law from its own array, an interface controller in its observation (obs.F)
    Fsens = model.F.copy() if fast else ctrl.F
    iF, iFs, iC = ROW_SLICES["F_true"].start, ROW_SLICES["F_sensed"].start, ROW_SLICES["contact"].start
    xd, dxd, ddxd = np.zeros(2), np.zeros(2), np.zeros(2)
    T1, T2, u2, deN = np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6)
    ref = np.concatenate([s0[4:10], s0[10:16]])  # servo reference [q2_ref, dq2_ref]
    servo = plant.actuation == "servo"
    delay = int(round(scn.plant.actuation_delay / dt))
    cmdbuf = np.zeros((delay + 1, 26))  # [T1, T2, q2_ref, dq2_ref, sensed q2] per slot
    cmdbuf[:, 8:20] = ref
    # the plant.command arguments of each slot, as views made once
    views = [(c[0:2], c[2:8], c[8:14], c[14:20], c[20:26]) for c in cmdbuf]
    command, advance, true_state = plant.command, plant.advance, plant.true_state
    record = plant.record if own_geo else None
    check, after = K.stepped_state_check, K.stepped_after_control
    no_ref = np.zeros(0)
    ref_mode = 1 if servo else 0
    slots = delay + 1
    # the paper's law: check, laws and the glue of `after` in one compiled call
    one = K.stepped_paper_step if fast else None
    minfo, sinfo = np.empty(MASTER_INFO), np.empty(SLAVE_INFO)
    bar = progress_bar(progress, n, f"{plant.kind} plant ({plant.actuation}), controller {cname}")
    status, done = 0, 0
    interrupted = False
    t0 = time.perf_counter()
    try:
        for k in range(n):
            t = k * dt
            st = true_state(state)
            if st:
                status = int(st)
                break
            if plant_forces is not None:
                plant_forces(Ftrue, cinfo)
            row = rows[k]
            if one is not None:  # the paper's controller: check, laws, row, glue in one compiled call
                s0, st = one(state, EXPLODING, Ftrue, ignored, t, traj_p, noise, k, scale, a.mpk_c, a.spk_c,
                             a.nodes, a.weights, a.gains, a.spec, Fsens, xd, dxd, ddxd, sensed, T1, T2, u2,
                             deN, minfo, sinfo, row, cinfo, iF, iFs, iC, ref_mode, ref, dt, cmdbuf[k % slots])
                if s0:
                    status = s0
                    break
            else:
                st = check(state, EXPLODING, Ftrue, Fsens, ignored)  # status 8 / 5; Fsens <- the sensed F
                if st:
                    status = st
                    break
                K.desired(traj_p, t, xd, dxd, ddxd)
                K.sense_state(state, noise, k, scale, sensed)
                st = int(ctrl.step(t, sensed, xd, dxd, ddxd, T1, T2, u2, deN))
                K.record_row(t, state, xd, dxd, mpk, gains, spec, T1, T2, u2, deN, row)
                ext = no_ref
                if servo and ctrl.use_ref:
                    ext, ref_mode = ctrl.ref, 2
                elif servo:
                    ref_mode = 1
                # row's F / contact columns, status 1 / 4, the servo reference, the command slot of step k
                st = after(st, T1, T2, u2, row, Ftrue, Fsens, cinfo, iF, iFs, iC, ref_mode, ext, ref, dt,
                           sensed, cmdbuf[k % slots])
            if record is not None:
                record(k)
            else:
                tips[k] = plant.slave_tip()
                for name, v in plant.geometry().items():
                    geo[name][k] = v
            done = k + 1
            if st != 0:
                status = int(st)
                break
            command(*views[(k - delay) % slots if k >= delay else 0])
            st = advance(dt)
            if st != 0:
                status = int(st)
                break
            if (k + 1) % CHUNK == 0:
                if bar is not None:
                    bar.update(CHUNK)
                if on_chunk is not None:
                    part = Trajectory.from_rows(rows[k + 1 - CHUNK:k + 1])
                    part.meta.update(run_meta(scn, 0.0))
                    on_chunk(part)
                if STOP.is_set():
                    interrupted = True
                    break
    except KeyboardInterrupt:
        interrupted = True
    except ControllerFailure as exc:  # one line naming the controller, the step and the time
        error, failed = str(exc), True
    except Exception as exc:  # keep what was computed; report the cause
        error = f"{type(exc).__name__}: {exc}"
    finally:
        if bar is not None:
            bar.close()
        if ctrl is not None:
            ctrl.close()
    wall = time.perf_counter() - t0
    traj = Trajectory.from_rows(rows[:done])
    traj.meta.update(run_meta(scn, wall))
    traj.meta["build_time"] = build_time
    traj.meta["controller"] = cname
    if own_geo:
        plant.finish(traj, done)
    else:
        traj.x2_plant = tips[:done].copy()
        if "master" in geo:
            traj.master_pos = geo.pop("master")[:done].copy()
        traj.meta["geometry"] = {name: v[:done].copy() for name, v in geo.items()}
        traj.meta.update(getattr(plant, "meta", lambda: {})())
    if status == -1:  # a controller gave up (ControllerDiverged without a status code)
        traj.status, traj.message = "diverged", ctrl.diverged or "controller gave up"
    elif failed:
        traj.status, traj.message = "error", error
        traj.meta["failed_controller"] = cname
    else:
        set_outcome(traj, status, interrupted, error)
    return traj
