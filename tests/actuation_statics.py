"""Independent references for the actuation tests: the static hold of a commanded CC shape on the free
MuJoCo chain (Newton on MuJoCo's own generalized forces, Jacobian by finite differences) and its
linearized continuous-time modes (stiffness and damping by finite differences of the same forces,
M from mj_fullM).  Test helpers only (not production code)."""

from __future__ import annotations

import mujoco
import numpy as np

from controllers import slave as slave_model
from controllers.params import MasterParams, SlaveParams
from harness.config.scenario import PlantConfig
from harness.plant.mujoco_model import build_model

# a bent shape with unequal sections where both muscle groups of every section hold it in [0, F_max]
Q2_HOLD = np.array([0.36, 0.35, 0.34, 0.6, -0.5, 0.8])


def hold_T2(slave: SlaveParams, q2) -> np.ndarray:
    """The generalized force that holds q2 at rest on the analytic model: gravity + elastic (N, N m^2)."""
    return slave_model.gravity_force(slave, q2) + slave_model.elastic_force(slave, q2)


class Hold:
    """The free chain (N segments, actuation) commanded to hold q2 against gravity."""

    def __init__(self, N: int, actuation: str, q2=Q2_HOLD, slave: SlaveParams | None = None, **plant):
        self.slave = SlaveParams() if slave is None else slave
        self.q2 = np.asarray(q2, dtype=float)
        self.m, self.cm = build_model(MasterParams(), self.slave,
                                      PlantConfig(segments=N, actuation=actuation, **plant))
        self.d = mujoco.MjData(self.m)
        self.actuation = actuation
        cm, d = self.cm, self.d
        self.dof = np.asarray(cm.chain_dof_adr)
        self.qadr = np.asarray(cm.chain_qpos_adr)
        T2 = hold_T2(self.slave, self.q2)
        self.force = np.zeros(cm.n_chain)  # constant joint forces (torque mode)
        if actuation == "servo":  # the servo holds its reference; no feed-forward
            d.ctrl[cm.chain_actuator_ids] = cm.joints_from_q2(self.q2)
        elif actuation == "torque":
            self.force = cm.force_from_T2(self.q2, T2)
        else:
            cmd, self.n_sat = cm.muscle_commands(self.q2, T2)
            d.ctrl[cm.muscle_actuator_ids] = cmd
            d.act[:] = d.ctrl[cm.muscle_actuator_ids]  # force state at its steady value
        self.ctrl = d.ctrl.copy()

    def forces(self, q, v) -> np.ndarray:
        """Net generalized force on the chain joints at chain positions q, velocities v (N or N m)."""
        m, d, cm = self.m, self.d, self.cm
        d.qpos[self.qadr] = q
        d.qvel[self.dof] = v
        mujoco.mj_forward(m, d)
        corr = cm.elastic_correction(q)
        return (d.qfrc_passive + d.qfrc_actuator - d.qfrc_bias)[self.dof] + corr + self.force

    def solve(self, tol: float = 1e-10, max_iter: int = 30) -> np.ndarray:
        """Static equilibrium chain positions (Newton from the commanded CC shape)."""
        q = self.cm.joints_from_q2(self.q2)
        v0 = np.zeros_like(q)
        scale = np.abs(self.forces(q, v0)).max() + 1.0
        for _ in range(max_iter):
            f = self.forces(q, v0)
            if np.abs(f).max() < tol * scale:
                break
            K = self.jac(q, v0, wrt="q")
            q = q - np.linalg.solve(K, f)
        else:
            raise RuntimeError("static hold: Newton did not converge")
        self.q_eq = q
        return q

    def jac(self, q, v, wrt: str, h: float = 1e-7) -> np.ndarray:
        n = q.size
        J = np.empty((n, n))
        for c in range(n):
            dq = np.zeros(n)
            dq[c] = h
            if wrt == "q":
                J[:, c] = (self.forces(q + dq, v) - self.forces(q - dq, v)) / (2 * h)
            else:
                J[:, c] = (self.forces(q, v + dq) - self.forces(q, v - dq)) / (2 * h)
        return J

    def tip(self) -> np.ndarray:
        """[X, Z] (m) of the tip site at the equilibrium, relative to the Octarm base."""
        self.d.qpos[self.qadr] = self.q_eq
        mujoco.mj_kinematics(self.m, self.d)
        return self.cm.octarm_tip(self.m, self.d)

    def modes(self) -> np.ndarray:
        """Continuous-time eigenvalues (1/s) of the chain linearized at the equilibrium, actuator states
        and commands held: x' = [v, M^-1 (K dq + D dv)]."""
        q, v = self.q_eq, np.zeros_like(self.q_eq)
        K, D = self.jac(q, v, "q"), self.jac(q, v, "v")
        self.d.qpos[self.qadr] = q
        self.d.qvel[:] = 0.0
        mujoco.mj_forward(self.m, self.d)
        M = np.zeros((self.m.nv, self.m.nv))
        mujoco.mj_fullM(self.m, self.d, M)
        Mi = np.linalg.inv(M[np.ix_(self.dof, self.dof)])
        n = q.size
        A = np.block([[np.zeros((n, n)), np.eye(n)], [Mi @ K, Mi @ D]])
        return np.linalg.eigvals(A)

    def first_mode(self) -> float:
        """|lambda| / (2 pi) (Hz) of the slowest mode: the natural frequency of the first bending mode
        (a lightly damped pair under torque and muscle actuation; an overdamped real eigenvalue under the
        critically damped servos, where this is its decay rate over 2 pi)."""
        lam = self.modes()
        return float(np.abs(lam).min() / (2 * np.pi))


def step_map_modes(h: Hold, eps: float = 1e-6) -> np.ndarray:
    """Continuous-time eigenvalues log(mu) / dt of the one-physics-step map of the chain at the hold (mu
    its eigenvalues), linearized by centred finite differences through mj_step with the elastic
    correction recomputed before the step, as the loop applies it (mjd_transitionFD would hold
    qfrc_applied, and with it the correction, fixed)."""
    m, cm = h.m, h.cm
    d = mujoco.MjData(m)
    n = h.q_eq.size
    act0 = h.d.act.copy()

    def step(x):
        mujoco.mj_resetData(m, d)
        d.qpos[h.qadr] = x[:n]
        d.qvel[h.dof] = x[n:]
        d.ctrl[:] = h.ctrl
        d.act[:] = act0
        d.qfrc_applied[h.dof] = cm.elastic_correction(x[:n]) + h.force
        mujoco.mj_step(m, d)
        return np.concatenate([d.qpos[h.qadr], d.qvel[h.dof]])

    x0 = np.concatenate([h.q_eq, np.zeros(n)])
    A = np.empty((2 * n, 2 * n))
    for c in range(2 * n):
        dx = np.zeros(2 * n)
        dx[c] = eps
        A[:, c] = (step(x0 + dx) - step(x0 - dx)) / (2 * eps)
    return np.log(np.linalg.eigvals(A).astype(complex)) / m.opt.timestep
