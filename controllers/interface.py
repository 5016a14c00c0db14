"""The controller interface: what a controller receives every control step and what it returns.

A controller is a class with

* ``reset(ctx: ControllerContext) -> None`` once before the run (the scenario as the controller may
  see it: nominal models, gains, control period, plant actuation, its validated parameters);
* ``step(obs: Observation) -> Action`` once per control step (period ``ctx.dt``).

Frames and units (as everywhere in the harness): planar task space x = [X, Z] in metres, Z up,
relative to each arm's base; master joints q1 = [q_a, q_b] (rad); slave q2 = [d1, d2, d3, k1, k2, k3]
(section arc lengths m, curvatures 1/m); forces N, moments N m.

Observation (filled in place by the harness, never re-allocated; read it, do not keep references
past the step):
  t (s); k (step index); q1, dq1 (2,); q2, dq2 (6,) -- the *sensed* states (true state + the
  scenario's AWGN, see harness.loop.kernels.add_noise), views of ``sensed`` (16,) = [q1, dq1, q2,
  dq2]; x_d, dx_d, ddx_d (2,) the desired master-tip trajectory, paper eq. (40); F1, F2 (2,) the
  interaction forces of (1) when the plant provides them (the scenario's ``interaction_forces``),
  zeros otherwise.

Action (the controller owns one, preallocated by ``Controller.__init__``; write into its arrays):
  T1 (2,) master joint torques (N m), paper eq. (12);
  T2 (6,) slave generalized forces (N on d_i, N m on k_i), paper eq. (17): drives a torque plant
      (MuJoCo ``actuation = "torque"``, the analytic plant) and is the servo feed-forward otherwise;
  u2 (6,) commanded slave acceleration ddq2 (paper eq. (18)): a servo plant integrates it into its
      reference, q2_ref' = dq2_ref, dq2_ref' = u2 (semi-implicit Euler over dt);
  q2_ref, dq2_ref (6,) with ``use_ref = True``: the servo reference given directly (resolved-rate
      controllers), instead of integrating u2;
  deN (6,) optional diagnostic: the null-space error of eq. (23) (recorded; zeros if unused).

Which slave command a controller provides is its ``actuations`` tuple ("torque" needs T2, "servo"
needs u2 or the reference); the harness rejects a mismatch with the plant before running.

Parameters: a controller declares ``Params`` (a frozen dataclass with defaults, optional ``check()``
raising ParamsError, see `check_range`); the harness decodes ``[controller] params`` into it with the
scenario's validator (one-line errors naming ``controller.params.<key>``).

The nominal analytic models are available as plain functions bound to the nominal parameters:
`NominalModels` (``ctx.models``).  With the compiled kernels (the harness passes them) a call costs
microseconds; the maths is the interpreted ``controllers/`` code either way.
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import control, master, slave, subtasks, tip
from .params import Gains, MasterParams, SlaveParams, SubtaskSpec


class ParamsError(ValueError):
    """A controller parameter is invalid.  One line: ``controller.params.<key> = <value>: <why>``."""

    def __init__(self, key: str, value: Any, why: str) -> None:
        super().__init__(f"controller.params.{key} = {value!r}: {why}")
        self.key = key


class ControllerDiverged(RuntimeError):
    """Raised by a controller that detects that it cannot continue (e.g. a singular Jacobian); the run
    stops with status "diverged" (not "error").  `code`: a status code of controllers.status."""

    def __init__(self, message: str, code: int = 0) -> None:
        super().__init__(message)
        self.code = code


class Observation:
    """What a controller sees at one control step (see the module docstring).  All arrays are views of
    buffers owned by the harness and overwritten every step."""

    __slots__ = ("t", "k", "sensed", "q1", "dq1", "q2", "dq2", "x_d", "dx_d", "ddx_d", "F", "F1", "F2")

    def __init__(self) -> None:
        self.t = 0.0
        self.k = 0
        self.sensed = np.zeros(16)
        self.q1, self.dq1 = self.sensed[0:2], self.sensed[2:4]
        self.q2, self.dq2 = self.sensed[4:10], self.sensed[10:16]
        self.x_d, self.dx_d, self.ddx_d = np.zeros(2), np.zeros(2), np.zeros(2)
        self.F = np.zeros(4)  # [F1, F2]
        self.F1, self.F2 = self.F[0:2], self.F[2:4]


class Action:
    """What a controller commands at one control step (see the module docstring)."""

    __slots__ = ("T1", "T2", "u2", "deN", "q2_ref", "dq2_ref", "use_ref")

    def __init__(self) -> None:
        self.T1 = np.zeros(2)
        self.T2 = np.zeros(6)
        self.u2 = np.zeros(6)
        self.deN = np.zeros(6)
        self.q2_ref = np.zeros(6)
        self.dq2_ref = np.zeros(6)
        self.use_ref = False


class NominalModels:
    """The nominal analytic models (controllers/) bound to the nominal parameters.

    `kernels`: a namespace holding the controllers/ kernels (the harness passes the compiled ones,
    `harness.loop.fast.K`); default: the interpreted functions (same maths, slower).  Every method
    returns views of buffers owned by this object (valid until the next call of the same method).
    """

    def __init__(self, master_p: MasterParams, slave_p: SlaveParams, subtask: SubtaskSpec | None = None,
                 kernels: Any = None) -> None:
        if kernels is None:
            kernels = types.SimpleNamespace(master_kernel=master.master_kernel,
                                            tip_kinematics=tip.tip_kinematics,
                                            mass_nle_kernel=slave.mass_nle_kernel,
                                            pinv_terms=control.pinv_terms,
                                            control_laws=control.control_laws)
        self._k = kernels
        self.master_params, self.slave_params = master_p, slave_p
        self.mpk = master.packed(master_p)
        self.spk = slave_p.packed()
        self.nodes, self.weights = slave.gauss_legendre01(slave_p.n_quad)
        self.spec = subtasks.pack_subtask(subtask if subtask is not None else SubtaskSpec(), slave_p)
        self._x1, self._J1, self._Jd1 = np.empty(2), np.empty((2, 2)), np.empty((2, 2))
        self._M1, self._N1 = np.empty((2, 2)), np.empty(2)
        self._x2, self._J2, self._Jd2 = np.empty(2), np.empty((2, 6)), np.empty((2, 6))
        self._H, self._Hd = np.empty((2, 6, 6)), np.empty((2, 6, 6))
        self._M2, self._N2, self._G2 = np.empty((6, 6)), np.empty(6), np.empty(6)
        self._Mg, self._zero = np.empty((6, 6)), np.zeros(6)
        self._Jp, self._Jpd = np.empty((6, 2)), np.empty((6, 2))

    def master(self, q1, dq1):
        """Master model (Sec. II-C): x1 (2,) tip [X, Z] m, J1 (2,2), dJ1/dt (2,2), M1 (2,2) kg m^2,
        N1 (2,) = C1 dq1 + G1 + B1 dq1 (N m): M1 ddq1 + N1 = T1 + J1^T F1, eq. (1)."""
        self._k.master_kernel(self.mpk, q1, dq1, self._x1, self._J1, self._Jd1, self._M1, self._N1)
        return self._x1, self._J1, self._Jd1, self._M1, self._N1

    def slave_kinematics(self, q2, dq2):
        """Slave tip kinematics (constant curvature): x2 (2,) m, J2 (2,6), dJ2/dt (2,6)."""
        self._k.tip_kinematics(q2, dq2, 2, self._x2, self._J2, self._H, self._Hd)
        np.einsum("iab,b->ia", self._H, dq2, out=self._Jd2)
        return self._x2, self._J2, self._Jd2

    def slave_dynamics(self, q2, dq2):
        """Slave Lagrangian dynamics: M2 (6,6), N2 (6,) = C2 dq2 + G2 + K2 + D2 dq2 (gravity, elastic,
        damping) so that M2 ddq2 + N2 = T2 + J2^T F2, eq. (1)."""
        self._k.mass_nle_kernel(self.spk, q2, dq2, self.nodes, self.weights, self._M2, self._N2)
        return self._M2, self._N2

    def slave_static(self, q2):
        """Static generalized forces G2(q2) + K2(q2) (6,): gravity and elasticity, = N2 at dq2 = 0."""
        self._k.mass_nle_kernel(self.spk, q2, self._zero, self.nodes, self.weights, self._Mg, self._G2)
        return self._G2

    def paper_law(self, gains, sensed, xd, dxd, ddxd, F, T1, T2, u2, deN, minfo, sinfo) -> int:
        """The paper's whole law (12)-(13), (17)-(18), (23)-(33) on the sensed state (16,)
        (`controllers.control.control_laws`, the kernel of the harness' compiled loops): gains = packed
        gains + [e2_sign, null_space_scale]; writes T1, T2, u2, deN, minfo, sinfo.  Returns a status code
        (`controllers.status`)."""
        return self._k.control_laws(self.mpk, self.spk, self.nodes, self.weights, gains, self.spec, sensed,
                                    xd, dxd, ddxd, F, T1, T2, u2, deN, minfo, sinfo)

    def pinv(self, J2, dJ2):
        """J2^+ = J2^T (J2 J2^T)^-1 (6,2), eq. (7), and its exact time derivative (6,2); and
        det(J2 J2^T) (<= 1e-14: singular, J2^+ not written)."""
        det = self._k.pinv_terms(J2, dJ2, self._Jp, self._Jpd)
        return self._Jp, self._Jpd, det


@dataclass(frozen=True)
class ControllerContext:
    """The scenario as a controller sees it at `reset` (everything on the nominal/controller side).

    dt: control period (s); n_steps; actuation: "torque" or "servo" (what the plant needs);
    plant: plant kind (informational; a controller must not depend on the plant's parameters);
    master, slave, gains, subtask: the nominal models and the paper's gains (39) and sub-task;
    F: (2, 2) interaction forces [F1, F2] of the scenario (N); seed: the scenario seed;
    params: the controller's validated `Params` instance (None without `Params`);
    models: `NominalModels` bound to master/slave; q0 (16,): the initial sensed state is in the first
    Observation, q0 is the noise-free initial state (for servo references); faults: (e2_sign,
    null_space_scale) of the scenario's [faults] (deliberate faults of the paper's law, for mutation
    tests of bounds files; other controllers may ignore them)."""

    dt: float
    n_steps: int
    actuation: str
    plant: str
    master: MasterParams
    slave: SlaveParams
    gains: Gains
    subtask: SubtaskSpec
    F: np.ndarray
    seed: int
    params: Any
    models: NominalModels
    q0: np.ndarray
    faults: tuple = (1, 1.0)


def check_range(key: str, value: float, lo: float | None = None, hi: float | None = None,
                lo_open: bool = False) -> None:
    """Raise ParamsError unless lo (<, or <= with lo_open) value <= hi."""
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ParamsError(key, value, f"must be {'>' if lo_open else '>='} {lo:g}")
    if hi is not None and value > hi:
        raise ParamsError(key, value, f"must be <= {hi:g}")


class Controller:
    """Base class of every controller (built-in or user).  Subclasses set the class attributes and
    implement `reset` and `step`; see the module docstring for the data.

    name: short name (built-ins: the name used by ``--controller``); description: one line;
    actuations: the plant actuations it supports ("torque": it computes T2; "servo": it computes u2
    or the servo reference); plants: the plant kinds it runs on ("mujoco", "analytic", "cosserat"; None:
    any); requires: plant settings it needs, {plant kind: {dotted scenario key: value}} (e.g.
    ``{"mujoco": {"plant.enforce_cc": True}}``: on the MuJoCo plant only the constant-curvature chain);
    Params: a frozen dataclass of parameters with defaults (optional method ``check(self)`` raising
    ParamsError) or None.  The harness checks actuations, plants and requirements before a run and says
    in one line what does not match."""

    name = "controller"
    description = ""
    actuations: tuple[str, ...] = ("torque", "servo")
    plants: tuple[str, ...] | None = None
    requires: dict[str, dict[str, object]] = {}  # noqa: RUF012 - read only
    Params: type | None = None

    def __init__(self) -> None:
        self.action = Action()
        self.ctx: ControllerContext | None = None

    def reset(self, ctx: ControllerContext) -> None:
        """Called once before the first step.  Default: keep the context, zero the action."""
        self.ctx = ctx
        a = self.action
        for arr in (a.T1, a.T2, a.u2, a.deN, a.q2_ref, a.dq2_ref):
            arr[:] = 0.0
        a.use_ref = False

    def step(self, obs: Observation) -> Action:  # pragma: no cover - abstract
        raise NotImplementedError


__all__ = ["Action", "Controller", "ControllerContext", "ControllerDiverged", "NominalModels", "Observation",
           "ParamsError", "check_range"]
