"""The MuJoCo and analytic plants as `harness.plant.stepped.SteppedPlant`s for `harness.loop.stepped_loop`,
with the kernels of their compiled loops (the paper's law through the interface gives the compiled loop's
numbers bit for bit)."""

from __future__ import annotations

import mujoco
import numpy as np

from controllers import master as master_model
from controllers.control import MASTER_INFO, SLAVE_INFO
from controllers.params import Q2_NAMES
from controllers.status import Status
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.loop.common import RunModel
from harness.loop.fast import K
from harness.loop.mj_warnings import warning_counts
from harness.loop.mujoco_loop import Geometry, make_plant, plant_groups
from harness.plant.mujoco_model import MujocoPlant

FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


class MujocoStepped:
    """The MuJoCo plant of `harness.loop.mujoco_loop`, stepped from Python with its kernels."""

    kind = "mujoco"

    def __init__(self, scn: Scenario, model: RunModel, plant=None) -> None:
        for key, used in (("operator.enabled", scn.operator.enabled),
                          ("sensing.force.mode", scn.sensing.force.mode == "sensed")):
            if used:
                raise ConfigError(f"{key}: needs the compiled MuJoCo loop (controller.name = 'paper'); the "
                                  "Python-stepped MuJoCo plant does not simulate it", path=key)
        plant = plant if plant is not None else MujocoPlant.build(scn)
        m, d, cmap = self.m, self.d, self.cmap = make_plant(scn, plant, model.s0)  # at the initial state
        self.geo = Geometry(m, d, cmap, scn.n_steps, live=False)
        rec = (np.zeros((0, m.nq)), np.zeros((0, m.nu + m.nv)), self.geo.inputs, self.geo.rec)
        self.p = plant_groups(scn, m, d, cmap, plant.contact, model, 0, rec)
        _mj, self.master, self.chain, self.sensing, _op, _rec, self.act = self.p
        if plant.contact is None:  # no contact sensors: the loop's constant forces, no call per step
            self.forces = None
        self.actuation = scn.plant.actuation
        self.physics_dt = scn.control_dt / max(1, scn.substeps)
        self.cmd = np.zeros(2 + 2 * cmap.n_chain)  # [master torque, chain ctrl (n), chain feed-forward (n)]
        self.warned: dict[str, int] = {}
        self.full = None  # the physics state kept by get_state(keep=True)

    def reset(self, state0: np.ndarray) -> None:  # `make_plant` put the plant at the initial state
        pass

    def true_state(self, state: np.ndarray) -> int:
        K.sense_mujoco(self.master, self.chain, state)
        return Status(K.mujoco_state_status(state))

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed) -> None:
        ref = self.act[8]
        self.cmd[0:2] = T1
        ref[0:6] = q2_ref
        ref[6:12] = dq2_ref
        K.chain_commands(self.act, q2_sensed, T2, self.cmd)

    def advance(self, dt: float) -> int:  # noqa: ARG002 - the scenario's substeps of mj_step
        st = K.mujoco_advance(0, 0, self.cmd, None, None, self.p)
        if st:
            self.warned = warning_counts(self.d.warning.number)
        return Status(st)

    def forces(self, F: np.ndarray, contact: np.ndarray) -> None:
        """The true forces (4,) ON the robots (constant + contact on the tip body), contact summary (5,)."""
        sensordata, cadr, _cpts, nopts, Fc = self.sensing[:5]
        F2c = self.sensing[12]
        K.read_contact(sensordata, cadr, F2c, contact, nopts)
        F[0:2] = Fc[0:2] + 0.0  # as `mujoco_kernels.mujoco_sense`: + the operator's force, none here
        F[2:4] = Fc[2:4] + F2c

    def record(self, k: int) -> None:
        self.geo.qpos_hist[k] = self.d.qpos

    def finish(self, traj, done: int) -> None:
        self.geo.finish(traj, done, self.warned, int(self.act[9][0]))

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
        self.physics_dt = scn.control_dt / max(1, scn.substeps)
        self.state = model.s0.copy()
        self.cmd = np.zeros(8)  # [T1, T2], held over the step
        # `analytic_advance`'s law buffers (unused: the commands are held) and plant arguments
        self.law = (np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(MASTER_INFO),
                    np.zeros(SLAVE_INFO), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(16))
        self.args = (model, np.zeros(4), scn.control_dt, max(1, scn.substeps), False,
                     master_model.packed(plant.master), plant.slave.packed(), np.empty((4, 16)), np.empty(16))

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

    def advance(self, dt: float) -> int:  # noqa: ARG002 - the scenario's control_dt
        return Status(K.analytic_advance(0, 0, self.cmd, self.state, self.law, self.args))

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
