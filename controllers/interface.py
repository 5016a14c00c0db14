"""The controller protocol: ``reset(ctx)`` once, then ``step(obs) -> Action`` every control period
``ctx.dt``.  Units, frames and fields: docs/guide/controllers.md; q2 = [d1, d2, d3 (m), k1, k2, k3 (1/m)].
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import control, master, slave, subtasks, tip
from .params import Gains, MasterParams, SlaveParams, SubtaskSpec


class ParamsError(ValueError):
    """One line: ``controller.params.<key> = <value>: <why>``."""

    def __init__(self, key: str, value: Any, why: str) -> None:
        super().__init__(f"controller.params.{key} = {value!r}: {why}")
        self.key = key


class ControllerDiverged(RuntimeError):
    """The controller cannot continue: the run stops as "diverged"; `code`: a `controllers.status` code."""

    def __init__(self, message: str, code: int = 0) -> None:
        super().__init__(message)
        self.code = code


class Observation:
    """What a controller sees at one step; views of harness buffers overwritten every step:
    t (s), k (step index); sensed (16,) = [q1, dq1, q2, dq2]: true state + the scenario's noise, with
    views q1, dq1 (2,), q2, dq2 (6,); x_d, dx_d, ddx_d (2,): desired master tip, eq. (40); F (4,) =
    [F1, F2] (2,) each: interaction forces of (1) when the plant provides them, else zeros."""

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
    """What a controller commands at one step (preallocated; write into its arrays):
    T1 (2,) N m, eq. (12); T2 (6,) [N, N m], eq. (17): drives a torque plant, servo feed-forward
    otherwise; u2 (6,) commanded ddq2, eq. (18): a servo plant integrates it into its reference;
    q2_ref, dq2_ref (6,) with use_ref = True: the servo reference given directly; deN (6,): the
    null-space error (23), recorded (optional)."""

    __slots__ = ("T1", "T2", "u2", "deN", "q2_ref", "dq2_ref", "use_ref")

    def __init__(self) -> None:
        self.T1, self.T2, self.u2, self.deN = np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6)
        self.q2_ref, self.dq2_ref = np.zeros(6), np.zeros(6)
        self.use_ref = False


class NominalModels:
    """The nominal analytic models; kernels: namespace of compiled kernels (default interpreted).
    Methods return views of owned buffers, valid until the next call of the same method."""

    def __init__(self, master_p: MasterParams, slave_p: SlaveParams, subtask: SubtaskSpec | None = None,
                 kernels: Any = None) -> None:
        if kernels is None:
            kernels = types.SimpleNamespace(**{f.__name__: f for f in (
                master.master_kernel, tip.tip_kinematics, slave.mass_nle_kernel, control.pinv_terms,
                control.control_laws)})
        self._k = kernels
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
        """Slave dynamics, eq. (1): M2 (6,6), N2 (6,) = C2 dq2 + G2 + K2 + D2 dq2."""
        self._k.mass_nle_kernel(self.spk, q2, dq2, self.nodes, self.weights, self._M2, self._N2)
        return self._M2, self._N2

    def slave_static(self, q2):
        """Static generalized forces G2(q2) + K2(q2) (6,): gravity and elasticity, = N2 at dq2 = 0."""
        self._k.mass_nle_kernel(self.spk, q2, self._zero, self.nodes, self.weights, self._Mg, self._G2)
        return self._G2

    def paper_law(self, gains, sensed, xd, dxd, ddxd, F, T1, T2, u2, deN, minfo, sinfo) -> int:
        """The paper's whole law (`controllers.control.control_laws`); gains = packed gains + [e2_sign,
        null_space_scale].  Returns a status code."""
        return self._k.control_laws(self.mpk, self.spk, self.nodes, self.weights, gains, self.spec, sensed,
                                    xd, dxd, ddxd, F, T1, T2, u2, deN, minfo, sinfo)

    def pinv(self, J2, dJ2):
        """J2^+ = J2^T (J2 J2^T)^-1 (6,2), eq. (7), and its exact time derivative (6,2); and
        det(J2 J2^T) (<= 1e-14: singular, J2^+ not written)."""
        det = self._k.pinv_terms(J2, dJ2, self._Jp, self._Jpd)
        return self._Jp, self._Jpd, det


@dataclass(frozen=True)
class ControllerContext:
    """The scenario as a controller sees it at `reset`: dt (s); F (2, 2) [F1, F2] N; params: the
    validated `Params` or None; q0 (16,) noise-free initial state; faults: (e2_sign, null_space_scale)."""

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
    """Base class: set the class attributes, implement `reset` and `step`.  actuations: "torque" (T2)
    and/or "servo" (u2 or the reference); plants: plant kinds (None: any); requires: {plant kind: {dotted
    scenario key: value}}; Params: frozen dataclass (optional ``check()`` raising ParamsError) or None."""

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
