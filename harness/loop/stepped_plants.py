"""The MuJoCo and analytic plants as `harness.plant.stepped.SteppedPlant`s, stepped from Python by the
one Python-level loop (`harness.loop.stepped_loop`) for controllers that run in Python.  They live in
harness/loop because they use the loops' compiled kernels (`harness.loop.fast.K`).  Each adapter does
exactly what the compiled loop does around the control law, with the same compiled kernels, so the
paper's law through the interface gives the compiled loop's numbers bit for bit:

* `MujocoStepped`: sensing `sense_mujoco`, the state checks of `mujoco_chunk` (status 6, 5), the command
  maps of `mujoco_commands` (servo: chain joints at q2_ref with the velocity feed-forward, T2
  feed-forward at q2_ref; torque: the map of T2 at the sensed q2), per substep the elastic correction
  into qfrc_applied and `mujoco.mj_step` (the Python binding of the same C function), MuJoCo warnings
  (status 7).  The servo reference and the actuation delay are the loop's (as in the compiled loop:
  the commands of step k - delay, each mapped with its own step's q2).
* `AnalyticStepped`: the RK4 of `analytic_chunk` (`harness.loop.kernels.plant_substeps`) with the commands
  held over the control step.

Both record their own geometry (`record(k)`, `finish(traj, done)`) instead of per-step
`slave_tip()` / `geometry()`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from controllers import master as master_model
from controllers.control import MASTER_INFO, SLAVE_INFO
from controllers.status import Status
from harness.config.scenario import Scenario
from harness.loop.common import RunModel
from harness.loop.fast import K
from harness.loop.mujoco_loop import (
    _Geometry,
    _plant_geometry,
    chain_ctrl_ids,
    make_plant,
    muscle_args,
    warning_counts,
)

FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
Q2_NAMES = ("d1", "d2", "d3", "k1", "k2", "k3")


class MujocoStepped:
    """The MuJoCo plant of `harness.loop.mujoco_loop`, stepped from Python (`SteppedPlant`)."""

    kind = "mujoco"

    def __init__(self, scn: Scenario, model: RunModel, plant=None) -> None:
        self.m, self.d, self.cmap = make_plant(scn, plant, model.s0)
        c = self.cmap
        self.n = c.n_chain
        self.actuation = scn.plant.actuation
        self.servo = self.actuation == "servo"
        self.ff = bool(scn.plant.servo_feedforward)
        self.sub = scn.substeps
        self.physics_dt = scn.control_dt / max(1, self.sub)
        self.kv_over_kp = (np.divide(c.servo_kv, c.servo_kp, out=np.zeros(self.n), where=c.servo_kp > 0)
                           if self.servo else np.zeros(self.n))
        self.cmd = np.zeros(2 + 2 * self.n)  # [master torque, chain ctrl (n), chain feed-forward (n)]
        self.muscle, self.ctrl_ids = muscle_args(c), chain_ctrl_ids(c)
        self.saturated = 0  # muscle group-steps outside [0, F_max]
        self.ref = np.zeros(12)  # [q2_ref, dq2_ref] of the command being mapped
        self.qc, self.vc, self.corr = np.empty(self.n), np.empty(self.n), np.empty(self.n)
        self.geo = _Geometry(self.m, self.d, c, scn.n_steps, live=False)
        self.warned: dict[str, int] = {}
        self.full = None  # the physics state kept by get_state(keep=True)

    def reset(self, state0: np.ndarray) -> None:
        """The plant is at the scenario's initial state after construction (make_plant)."""

    def true_state(self, state: np.ndarray) -> int:
        d, c = self.d, self.cmap
        K.sense_mujoco(d.qpos, d.qvel, c.master_qpos_adr, c.master_dof_adr, c.chain_qpos_adr, c.chain_dof_adr,
                       c.R, c.L0, self.qc, self.vc, state)
        return Status(K.mujoco_state_status(state))

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed) -> None:
        c, cmd, ref = self.cmap, self.cmd, self.ref
        cmd[0] = T1[0]
        cmd[1] = T1[1]
        ref[0:6] = q2_ref
        ref[6:12] = dq2_ref
        self.saturated += K.chain_commands(self.servo, self.ff, q2_sensed, T2, ref, c.C, c.R, c.L0,
                                           self.kv_over_kp, self.muscle, cmd)

    def advance(self, dt: float) -> int:
        d, c, n, use = self.d, self.cmap, self.n, self.cmd
        d.ctrl[c.master_actuator_ids] = use[0:2]
        d.ctrl[self.ctrl_ids] = use[2:2 + self.ctrl_ids.shape[0]]
        wnum = d.warning.number
        for _ in range(self.sub):
            self.qc[:] = d.qpos[c.chain_qpos_adr]
            K.chain_elastic_correction(self.qc, *c.elastic_args, self.corr)
            d.qfrc_applied[c.chain_dof_adr] = use[2 + n:2 + 2 * n] + self.corr
            mujoco.mj_step(self.m, d)
            if wnum.any():
                self.warned = warning_counts(d.warning.number)
                return Status.MUJOCO_WARNING
        return 0

    def slave_tip(self) -> np.ndarray:
        """Tip site [X, Z] (2,), m, relative to the slave base."""
        tip, base = self.d.site_xpos[self.cmap.tip_site_id], self.cmap.octarm_base_pos
        return np.array([tip[0] - base[0], tip[2] - base[2]])

    def geometry(self) -> dict[str, np.ndarray]:
        return {}

    def record(self, k: int) -> None:
        self.geo.qpos_hist[k] = self.d.qpos

    @property
    def state_names(self) -> list[str]:
        """qpos (joint names), qvel ("<joint> (rate)"), act; hinge and slide joints only (nq == nv)."""
        m = self.m
        if m.nq != m.nv:
            raise NotImplementedError("plant: the MuJoCo model has ball or free joints (nq != nv); only "
                                      "hinge and slide joints are supported")
        jn = {int(m.jnt_qposadr[j]): m.joint(j).name or f"joint{j}" for j in range(m.njnt)}
        qn = [jn.get(i, f"qpos[{i}]") for i in range(m.nq)]
        return qn + [f"{n} (rate)" for n in qn] + [f"act[{i}]" for i in range(m.na)]

    def get_state(self, keep: bool = False) -> np.ndarray:
        """[qpos, qvel, act]; keep: also MuJoCo's whole physics state (time, warm start, ...)."""
        d = self.d
        if keep:
            self.full = np.empty(mujoco.mj_stateSize(self.m, FULL))
            mujoco.mj_getState(self.m, d, self.full, FULL)
        return np.concatenate([d.qpos, d.qvel, d.act])

    def set_state(self, x: np.ndarray) -> None:
        m, d = self.m, self.d
        if self.full is not None:
            mujoco.mj_setState(m, d, self.full, FULL)
        d.qpos[:] = x[:m.nq]
        d.qvel[:] = x[m.nq:m.nq + m.nv]
        d.act[:] = x[m.nq + m.nv:]
        mujoco.mj_forward(m, d)

    def finish(self, traj, done: int) -> None:
        traj.meta.update(_plant_geometry(self.m, self.cmap, self.geo, done, traj))
        traj.meta["mujoco_warnings"] = int(sum(self.warned.values()))
        traj.meta["mujoco_warning_counts"] = self.warned
        if self.actuation == "muscle":
            traj.meta["muscle_saturated_steps"] = int(self.saturated)


class AnalyticStepped:
    """The analytic plant (its own parameters) integrated with RK4, commands held over the step
    (`SteppedPlant`, torque actuation)."""

    kind = "analytic"
    actuation = "torque"

    def __init__(self, scn: Scenario, model: RunModel, plant=None) -> None:
        from harness.plant.analytic import AnalyticPlant

        if plant is None:
            plant = AnalyticPlant(scn.plant_master, scn.plant_slave)
        self.model = model
        self.mpk = master_model.packed(plant.master)
        self.spk = plant.slave.packed()
        self.nsub = max(1, scn.substeps)
        self.physics_dt = scn.control_dt / self.nsub
        self.state = model.s0.copy()
        self.T1, self.T2 = np.zeros(2), np.zeros(6)
        # the law's buffers of `plant_substeps` (unused: the commands are held) and its RK4 work arrays
        self.work = (np.zeros(4), np.zeros(6), np.zeros(6), np.zeros(MASTER_INFO), np.zeros(SLAVE_INFO),
                     np.zeros(2), np.zeros(2), np.zeros(2), *(np.empty(16) for _ in range(5)))

    state_names = ["q1[0]", "q1[1]", "dq1[0]", "dq1[1]", *Q2_NAMES, *(f"d{n}/dt" for n in Q2_NAMES)]

    def reset(self, state0: np.ndarray) -> None:
        self.state[:] = state0

    def get_state(self, keep: bool = False) -> np.ndarray:  # noqa: ARG002 - nothing besides the state
        return self.state.copy()

    def set_state(self, x: np.ndarray) -> None:
        self.state[:] = x

    def true_state(self, state: np.ndarray) -> int:
        state[:] = self.state
        return 0

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed) -> None:
        self.T1[:] = T1
        self.T2[:] = T2

    def advance(self, dt: float) -> int:
        s = self.state
        nsub = max(1, round(dt / self.physics_dt))
        F, u2, deN, minfo, sinfo, xd, dxd, ddxd, *ks = self.work
        st = K.plant_substeps(s, 0.0, dt / nsub, nsub, False, self.model, F, self.mpk, self.spk, self.T1,
                              self.T2, u2, deN, minfo, sinfo, xd, dxd, ddxd, *ks)
        if st != Status.OK:
            return Status(st)
        if not np.all(np.isfinite(s)):
            return Status.NONFINITE
        if np.any(s[4:7] <= 0.0):
            return Status.SECTION_LENGTH
        return 0

    def slave_tip(self) -> np.ndarray:
        return np.zeros(2)

    def geometry(self) -> dict[str, np.ndarray]:
        return {}

    def record(self, k: int) -> None:
        pass

    def finish(self, traj, done: int) -> None:
        pass


def stepped_plant(scn: Scenario, model: RunModel, plant=None):
    """The scenario's plant as a `SteppedPlant`: `plant` itself if it is one (the Cosserat rod), else the
    Python-stepped adapter of the analytic or MuJoCo plant."""
    if plant is not None and hasattr(plant, "advance"):
        return plant
    if scn.plant.kind == "analytic":
        return AnalyticStepped(scn, model, plant)
    if scn.plant.kind == "mujoco":
        return MujocoStepped(scn, model, plant)
    raise NotImplementedError(f"plant.kind = {scn.plant.kind!r} has no Python-stepped adapter yet")
