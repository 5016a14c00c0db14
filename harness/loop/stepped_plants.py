"""The MuJoCo and analytic plants as `harness.plant.stepped.SteppedPlant`s for `harness.loop.stepped_loop`,
with the kernels of their compiled loops (the paper's law through the interface gives the compiled loop's
numbers bit for bit)."""

from __future__ import annotations

import mujoco
import numpy as np

from controllers import master as master_model
from controllers.control import MASTER_INFO, SLAVE_INFO
from controllers.status import Status
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.loop.common import RunModel
from harness.loop.fast import K
from harness.loop.force_args import ForceArgs
from harness.loop.mujoco_loop import Geometry, actuation_args, make_plant, warning_counts
from harness.plant.mujoco_model import MujocoPlant

FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
Q2_NAMES = ("d1", "d2", "d3", "k1", "k2", "k3")


class MujocoStepped:
    """The MuJoCo plant of `harness.loop.mujoco_loop`, stepped from Python."""

    kind = "mujoco"

    def __init__(self, scn: Scenario, model: RunModel, plant=None) -> None:
        for key, used in (("operator.enabled", scn.operator.enabled),
                          ("sensing.force.mode", scn.sensing.force.mode == "sensed")):
            if used:
                raise ConfigError(f"{key}: needs the compiled MuJoCo loop (controller.name = 'paper'); the "
                                  "Python-stepped MuJoCo plant does not simulate it", path=key)
        plant = plant if plant is not None else MujocoPlant.build(scn)
        self.m, self.d, self.cmap = make_plant(scn, plant, model.s0)  # at the initial state
        d, c = self.d, self.cmap
        self.fa = ForceArgs(scn, self.m, d, c, plant.contact, 0, model.s0, model.F)
        # `mujoco_kernels.master_grip`'s groups: + q1, dq1, xm, vm, J1, Jd1, M1, N1; the operator off
        self.master = (d.qpos, d.qvel, c.master_qpos_adr, c.master_dof_adr, self.fa.mpk_p, np.zeros(2),
                       np.zeros(2), np.zeros(2), np.zeros(2), np.zeros((2, 2)), np.zeros((2, 2)),
                       np.zeros((2, 2)), np.zeros(2))
        self.operator = (False, self.fa.op, self.fa.targets, self.fa.hand, self.fa.target, np.zeros(2))
        self.apply1 = model.F[0] != 0.0 or model.F[1] != 0.0
        self.F2c, self.nopts = np.zeros(2), np.zeros((0, 6))
        if self.fa.cadr.shape[0] == 0:  # no contact sensors: the loop's constant forces, no call per step
            self.forces = None
        self.n = n = self.cmap.n_chain
        self.actuation = scn.plant.actuation
        self.servo = self.actuation == "servo"
        self.ff = bool(scn.plant.servo_feedforward)
        self.sub = scn.substeps
        self.physics_dt = scn.control_dt / max(1, self.sub)
        self.ctrl_ids, self.kv_over_kp, self.muscle = actuation_args(self.cmap, self.servo)
        self.cmd = np.zeros(2 + 2 * n)  # [master torque, chain ctrl (n), chain feed-forward (n)]
        self.saturated = 0  # muscle group-steps outside [0, F_max]
        self.ref = np.zeros(12)  # [q2_ref, dq2_ref] of the command being mapped
        self.qc, self.vc, self.corr = np.empty(n), np.empty(n), np.empty(n)
        self.geo = Geometry(self.m, self.d, self.cmap, scn.n_steps, live=False)
        self.warned: dict[str, int] = {}
        self.full = None  # the physics state kept by get_state(keep=True)

    def reset(self, state0: np.ndarray) -> None:  # `make_plant` put the plant at the initial state
        pass

    def true_state(self, state: np.ndarray) -> int:
        d, c = self.d, self.cmap
        K.sense_mujoco(d.qpos, d.qvel, c.master_qpos_adr, c.master_dof_adr, c.chain_qpos_adr, c.chain_dof_adr,
                       c.R, c.L0, self.qc, self.vc, state)
        return Status(K.mujoco_state_status(state))

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed) -> None:
        c, cmd, ref = self.cmap, self.cmd, self.ref
        cmd[0:2] = T1
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
            if self.apply1:  # the constant F1 on the master handle, J1^T F1
                K.master_grip(self.master, self.operator)
                K.master_handle_force(self.master, self.operator, self.fa.Fconst, d.qfrc_applied)
            self.qc[:] = d.qpos[c.chain_qpos_adr]
            K.chain_elastic_correction(self.qc, *c.elastic_args, self.corr)
            d.qfrc_applied[c.chain_dof_adr] = use[2 + n:2 + 2 * n] + self.corr
            mujoco.mj_step(self.m, d)
            if wnum.any():
                self.warned = warning_counts(wnum)
                return Status.MUJOCO_WARNING
        return 0

    def forces(self, F: np.ndarray, contact: np.ndarray) -> None:
        """The true forces (4,) ON the robots (constant + contact on the tip body), contact summary (5,)."""
        Fc = self.fa.Fconst
        K.read_contact(self.fa.sensordata, self.fa.cadr, self.F2c, contact, self.nopts)
        for i in range(2):
            F[i] = Fc[i] + 0.0
            F[2 + i] = Fc[2 + i] + self.F2c[i]

    def record(self, k: int) -> None:
        self.geo.qpos_hist[k] = self.d.qpos

    def finish(self, traj, done: int) -> None:
        self.geo.finish(traj, done, self.warned, self.saturated)

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


class AnalyticStepped:
    """The analytic plant (its own parameters), RK4 with the commands held over the step (torque)."""

    kind = "analytic"
    actuation = "torque"
    state_names = ["q1[0]", "q1[1]", "dq1[0]", "dq1[1]", *Q2_NAMES, *(f"d{n}/dt" for n in Q2_NAMES)]

    def __init__(self, scn: Scenario, model: RunModel, plant=None) -> None:
        from harness.plant.analytic import AnalyticPlant

        if plant is None:
            plant = AnalyticPlant(scn.plant_master, scn.plant_slave)
        self.model = model
        self.mpk = master_model.packed(plant.master)
        self.spk = plant.slave.packed()
        self.physics_dt = scn.control_dt / max(1, scn.substeps)
        self.state = model.s0.copy()
        self.cmd = np.zeros(8)  # [T1, T2], held over the step
        # `analytic_advance`'s law buffers (unused: the commands are held) and RK4 work arrays
        self.law = (np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(MASTER_INFO),
                    np.zeros(SLAVE_INFO), np.zeros(2), np.zeros(2), np.zeros(2))
        self.work = (np.zeros(4), np.empty((4, 16)), np.empty(16))

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
        self.cmd[0:2] = T1
        self.cmd[2:8] = T2

    def advance(self, dt: float) -> int:
        nsub = max(1, round(dt / self.physics_dt))
        F, ks, tmp = self.work
        plant = (self.model, F, dt, nsub, False, self.mpk, self.spk, ks, tmp)
        return Status(K.analytic_advance(0, 0, 0, self.cmd, self.state, self.law, plant))

    def record(self, k: int) -> None:
        """No plant geometry beyond the state."""

    def finish(self, traj, done: int) -> None:
        """No plant geometry beyond the state."""


def stepped_plant(scn: Scenario, model: RunModel, plant=None):
    """The scenario's plant as a `SteppedPlant`: `plant` if it is one (the rod), else its adapter."""
    if plant is not None and hasattr(plant, "advance"):
        return plant
    if scn.plant.kind == "analytic":
        return AnalyticStepped(scn, model, plant)
    if scn.plant.kind == "mujoco":
        return MujocoStepped(scn, model, plant)
    raise NotImplementedError(f"plant.kind = {scn.plant.kind!r} has no Python-stepped adapter yet")
