"""The Python-level closed loop: any controller (the paper's compiled law or a `controllers.interface`
Controller) on any plant stepped from Python (`harness.plant.stepped.SteppedPlant`); `Stepper` is also the
closed-loop map of `harness.studies.stability`."""

from __future__ import annotations

import time

import numpy as np

from controllers.control import MASTER_INFO, SLAVE_INFO
from harness.config.scenario import Scenario
from harness.loop.common import CHUNK, STOP, ChunkRun, RunModel, compile_model, noise_table, progress_bar
from harness.loop.fast import K
from harness.loop.force_kernels import CONTACT_INFO
from harness.loop.interface_adapter import ControllerFailure, InterfaceController, is_compiled
from harness.loop.trajectory import ROW_WIDTH, Trajectory
from harness.plant.stepped import SteppedPlant

_NO_REF = np.zeros(0)


class Stepper:
    """One control step of the closed loop on a stepped plant, with the run's buffers.  ctrl: an
    `InterfaceController`, or None for the paper's compiled law; noise: `noise_table`'s (default: none);
    record(k): called once step k is recorded.  Loop state: `ref` (12,) servo reference [q2_ref, dq2_ref],
    `cmdbuf` (delay + 1, 26) the actuation-delay ring of [T1, T2, q2_ref, dq2_ref, sensed q2]."""

    def __init__(self, scn: Scenario, plant: SteppedPlant, model: RunModel,
                 ctrl: InterfaceController | None = None, noise: tuple[np.ndarray, float] | None = None,
                 record=None) -> None:
        self.plant, self.model, self.ctrl, self.record = plant, model, ctrl, record
        self.dt = scn.control_dt
        self.noise, self.scale = noise if noise is not None else (np.zeros((1, 16)), 0.0)
        self.state = np.zeros(16)
        # true tip forces: a plant with `forces(F, contact)` (the rod's contact) gives them each step, else
        # the constant ones; the controller reads the sensed F (F_true, or zeros when ignored)
        self.forces = getattr(plant, "forces", None)
        self.Ftrue, self.cinfo = model.F.copy(), np.zeros(CONTACT_INFO)
        # `kernels.loop_chunk`'s law: T1, T2, u2, deN, minfo, sinfo, xd, dxd, ddxd, sensed
        self.law = (np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6), np.empty(MASTER_INFO),
                    np.empty(SLAVE_INFO), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(16))
        self.servo = plant.actuation == "servo"
        self.ref = np.concatenate([model.s0[4:10], model.s0[10:16]])
        self.delay = int(round(scn.plant.actuation_delay / self.dt))
        self.cmdbuf = np.zeros((self.delay + 1, 26))
        self.cmdbuf[:, 8:20] = self.ref
        self.views = [(c[0:2], c[2:8], c[8:14], c[14:20], c[20:26]) for c in self.cmdbuf]
        self.done = 0  # rows recorded
        Fsens = model.F.copy() if ctrl is None else ctrl.F
        self.loop = (self.state, self.noise, self.scale, self.Ftrue, Fsens, self.cinfo,
                     scn.sensing.force.mode == "ignored", self.ref, self.dt, self.servo)

    def step(self, k: int, row: np.ndarray) -> int:
        """Control step k: the plant's true state and checks (8, 5), the controller, the record row into row
        (ROW_WIDTH,) (`done` = k + 1) and checks (1, 4), the servo reference, then `plant.command` with the
        commands of step k - delay and `plant.advance` (only when the status is 0).  Returns the status."""
        ctrl, state = self.ctrl, self.state
        st = self.plant.true_state(state)
        if st:
            return int(st)
        if self.forces is not None:
            self.forces(self.Ftrue, self.cinfo)
        slot = self.cmdbuf[k % (self.delay + 1)]
        if ctrl is None:  # the paper's law: check, laws, row and glue in one compiled call
            s0, st = K.stepped_paper_step(k, self.model, self.loop, self.law, row, slot)
            if s0:
                return s0
        else:
            st = K.stepped_state_check(self.loop)
            if st:
                return st
            t = k * self.dt
            T1, T2, u2, deN, _mi, _si, xd, dxd, ddxd, sensed = self.law
            K.desired(self.model.traj, t, xd, dxd, ddxd)
            K.sense_state(state, self.noise, k, self.scale, sensed)
            st = int(ctrl.step(t, sensed, xd, dxd, ddxd, T1, T2, u2, deN))
            K.record_row(t, state, self.model, self.law, row, False)
            ext = ctrl.ref if self.servo and ctrl.use_ref else _NO_REF
            st = K.stepped_after_control(st, self.loop, self.law, ext, row, slot)
        if self.record is not None:
            self.record(k)
        self.done = k + 1
        if st:
            return int(st)
        self.plant.command(*self.views[K.ring_index(k, self.delay)])
        return int(self.plant.advance(self.dt) or 0)


def simulate_stepped(scn: Scenario, plant: SteppedPlant, progress: bool = False,
                     on_chunk=None, model: RunModel | None = None) -> Trajectory:
    """Run the scenario (its controller) on a stepped plant; returns the Trajectory (possibly cut short).
    on_chunk: called with every CHUNK steps as a `Trajectory`.  Without the plant's own `record` / `finish`:
    traj.x2_plant (n, 2) = `slave_tip()`, master_pos (n, 3, 3) = geometry()["master"], meta["geometry"] the
    rest.  meta: build_time, wall_time (s), MuJoCo's warning text as the compiled MuJoCo loop's."""
    tb = time.perf_counter()
    n = scn.n_steps
    model = model if model is not None else compile_model(scn)
    ctrl = None if is_compiled(scn) else InterfaceController(scn, model)
    cname = scn.controller.name
    failure = None  # the controller's ControllerFailure
    plant.reset(model.s0)
    if hasattr(plant, "stop"):  # a plant with long inner loops (the rod) checks the stop flag itself
        plant.stop = STOP
    if ctrl is not None:
        try:
            ctrl.reset(model)
        except ControllerFailure as exc:
            failure, n = exc, 0
    build_time = time.perf_counter() - tb
    rows = np.zeros((n, ROW_WIDTH))
    own_geo = hasattr(plant, "finish")
    tips = np.zeros((0 if own_geo else n, 2))
    geo = {} if own_geo else {name: np.zeros((n, *np.shape(v))) for name, v in plant.geometry().items()}

    def copy_geometry(k: int) -> None:
        tips[k] = plant.slave_tip()
        for name, v in plant.geometry().items():
            geo[name][k] = v

    stepper = Stepper(scn, plant, model, ctrl, noise_table(scn, scn.n_steps),
                      plant.record if own_geo else copy_geometry)

    def steps(k0: int, k1: int) -> tuple[int, int]:
        for k in range(k0, k1):
            status = stepper.step(k, rows[k])
            if status:
                return status, stepper.done - k0
        return 0, k1 - k0

    run = ChunkRun(scn, rows, CHUNK, progress_bar(progress, n, f"{plant.kind} plant ({plant.actuation}), "
                                                  f"controller {cname}"), on_chunk)
    try:
        run.run(steps)
    finally:
        run.done = stepper.done  # also after an exception inside a step
        if ctrl is not None:
            ctrl.close()
    if failure is None and isinstance(run.exc, ControllerFailure):
        failure, run.error = run.exc, ""
    done = run.done
    traj = run.trajectory(getattr(plant, "warned", None))
    traj.meta.update(build_time=build_time, controller=cname)
    if own_geo:
        plant.finish(traj, done)
    else:
        traj.x2_plant = tips[:done].copy()
        if "master" in geo:
            traj.master_pos = geo.pop("master")[:done].copy()
        traj.meta["geometry"] = {name: v[:done].copy() for name, v in geo.items()}
        traj.meta.update(getattr(plant, "meta", lambda: {})())
    if run.status == -1:  # a controller gave up (ControllerDiverged without a status code)
        traj.status, traj.message = "diverged", ctrl.diverged or "controller gave up"
    elif failure is not None:  # one line naming the controller, the step and the time
        traj.status, traj.message = "error", str(failure)
        traj.meta["failed_controller"] = cname
    return traj
