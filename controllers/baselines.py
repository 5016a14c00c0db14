"""Built-in controllers (`controllers.interface.Controller`) and their registry `BUILTINS`.

All keep the paper's master law (12)-(13) and differ in how the redundant slave follows the master tip:
`PaperController` (the whole law, "paper"), `PaperNoNullSpace` (phi_N = 0) and `DampedLeastSquaresIK`
(resolved rate on the servo reference).  The worked user example is examples/controllers/.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .control import DET_MIN, MASTER_INFO, SLAVE_INFO
from .interface import Action, Controller, ControllerContext, ControllerDiverged, Observation, check_range
from .status import Status


def paper_master_law(models, gains, obs: Observation, T1: np.ndarray) -> tuple:
    """Master law (12)-(13) on the sensed master state.  Writes T1 (2,) (N m); returns (x1, dx1, a1)
    (2,) each: tip, tip velocity and the commanded task acceleration a1 = ddx_d + k1 de1 + k2 e1."""
    x1, J1, Jd1, M1, N1 = models.master(obs.q1, obs.dq1)
    dx1 = J1 @ obs.dq1
    e1 = obs.x_d - x1  # (11)
    de1 = obs.dx_d - dx1
    a1 = obs.ddx_d + gains.k1 * de1 + gains.k2 * e1
    if J1[0, 0] * J1[1, 1] - J1[0, 1] * J1[1, 0] == 0.0:
        raise ControllerDiverged(Status.MASTER_SINGULAR.text, code=Status.MASTER_SINGULAR)
    u1 = np.linalg.solve(J1, a1 - Jd1 @ obs.dq1)  # (13)
    T1[:] = M1 @ u1 + N1 - J1.T @ obs.F1  # (12)
    return x1.copy(), dx1, a1


class PaperController(Controller):
    """The paper's law (12)-(13), (17)-(18), (23)-(33) through `NominalModels.paper_law` (the compiled
    loops' kernel: the same numbers).  "paper" runs compiled; "paper_interface" steps this class."""

    name = "paper"
    description = "the paper's law (12)-(13), (17)-(18) with null-space terms (23)-(33)"
    actuations = ("torque", "servo")

    def reset(self, ctx: ControllerContext) -> None:
        super().reset(ctx)
        self.gains = np.concatenate([ctx.gains.packed(), [float(ctx.faults[0]), float(ctx.faults[1])]])
        self.minfo, self.sinfo = np.empty(MASTER_INFO), np.empty(SLAVE_INFO)

    def step(self, obs: Observation) -> Action:
        a = self.action
        st = self.ctx.models.paper_law(self.gains, obs.sensed, obs.x_d, obs.dx_d, obs.ddx_d, obs.F, a.T1,
                                       a.T2, a.u2, a.deN, self.minfo, self.sinfo)
        if st != Status.OK:
            raise ControllerDiverged(Status(st).text, code=st)
        return a


class PaperNoNullSpace(Controller):
    """The paper's law without its null-space terms: (12)-(13) and (17)-(18) with phi_N = 0,
    u2 = J2^+ (ddx_d + k1 de1 + k2 e1 + k3 de2 + k4 e2 - dJ2 dq2), T2 = M2 u2 + N2 - J2^T F2 (the
    slave's self-motion is left uncontrolled)."""

    name = "paper_no_null"
    description = "paper's law (12)-(13), (17)-(18) without the null-space terms (phi_N = 0)"
    actuations = ("torque", "servo")

    def step(self, obs: Observation) -> Action:
        ctx, a = self.ctx, self.action
        g = ctx.gains
        x1, dx1, a1 = paper_master_law(ctx.models, g, obs, a.T1)
        x2, J2, Jd2 = ctx.models.slave_kinematics(obs.q2, obs.dq2)
        e2 = x1 - x2  # (16)
        de2 = dx1 - J2 @ obs.dq2
        A = J2 @ J2.T
        if A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0] <= DET_MIN:
            raise ControllerDiverged(Status.SLAVE_SINGULAR.text, code=Status.SLAVE_SINGULAR)
        v = a1 + g.k3 * de2 + g.k4 * e2 - Jd2 @ obs.dq2
        a.u2[:] = J2.T @ np.linalg.solve(A, v)  # (18), phi_N = 0
        M2, N2 = ctx.models.slave_dynamics(obs.q2, obs.dq2)
        a.T2[:] = M2 @ a.u2 + N2 - J2.T @ obs.F2  # (17)
        return a


class DampedLeastSquaresIK(Controller):
    """Closed-loop resolved-rate IK with a damped least-squares inverse (Wampler 1986) on the servo
    reference: dq_r = J^T (J J^T + lambda^2 I)^-1 (dx1 + K (x1 - f(q_r))), J = J2(q_r), q_r += dt dq_r
    (lengths clamped to [L0, max_extension L0]); T2 = G2(q_r) + K2(q_r) feed-forward; u2 records
    (dq_r - dq_r_prev) / dt.  Servo plants only.  Params: gain K (1/s), damping lambda (m)."""

    name = "dls_ik"
    description = "resolved-rate IK, damped least-squares J^T (J J^T + lambda^2 I)^-1, on the servo reference"
    actuations = ("servo",)

    @dataclass(frozen=True)
    class Params:
        gain: float = 20.0  # 1/s, K of the task-space error feedback
        damping: float = 0.01  # m, lambda of the damped least-squares inverse

        def check(self) -> None:
            check_range("gain", self.gain, 0.0, 1e4, lo_open=True)
            check_range("damping", self.damping, 0.0, 10.0)

    def reset(self, ctx: ControllerContext) -> None:
        super().reset(ctx)
        self.qr = ctx.q0[4:10].copy()
        self.dqr = np.zeros(6)
        self.lo, self.hi = ctx.slave.length_range
        self.eye = np.eye(2)
        self.action.use_ref = True

    def step(self, obs: Observation) -> Action:
        ctx, a, p = self.ctx, self.action, self.ctx.params
        x1, dx1, _ = paper_master_law(ctx.models, ctx.gains, obs, a.T1)
        x2, J, _ = ctx.models.slave_kinematics(self.qr, self.dqr)
        v = dx1 + p.gain * (x1 - x2)
        dq = J.T @ np.linalg.solve(J @ J.T + p.damping ** 2 * self.eye, v)
        a.u2[:] = (dq - self.dqr) / ctx.dt
        self.dqr[:] = dq
        self.qr += ctx.dt * dq
        np.clip(self.qr[0:3], self.lo, self.hi, out=self.qr[0:3])
        a.q2_ref[:] = self.qr
        a.dq2_ref[:] = dq
        a.T2[:] = ctx.models.slave_static(self.qr)
        a.use_ref = True
        return a


# name -> class; "paper" runs in the compiled fast path, "paper_interface" is the same class stepped
BUILTINS: dict[str, type[Controller]] = {
    "paper": PaperController,
    "paper_interface": PaperController,
    "paper_no_null": PaperNoNullSpace,
    "dls_ik": DampedLeastSquaresIK,
}
FAST_PATH = "paper"  # the registered name whose law the harness runs compiled

__all__ = ["BUILTINS", "FAST_PATH", "DampedLeastSquaresIK", "PaperController", "PaperNoNullSpace",
           "paper_master_law"]
