"""A complete user controller for the default plant: resolved-rate control of the servo reference with a
posture term in the null space.

Run it (the default plant: MuJoCo, servo actuation):
    teleop run --controller examples/controllers/resolved_rate.py:ResolvedRate --duration 5
    teleop run --controller examples/controllers/resolved_rate.py:ResolvedRate --duration 5 \
        --set controller.params.gain=10

Master: the paper's law (12)-(13) (the master stands for the operator's arm tracking x_d (40)).
Slave (6 joints, 2 task coordinates): the section servos track a reference q_r that this controller
integrates itself (Whitney 1969; closed-loop inverse kinematics on the reference: Sciavicco & Siciliano
1988; posture in the null space: Liegeois 1977):

    dq_r = J^+ (dx1 + K (x1 - f(q_r))) + (I - J^+ J) kq (q_r(0) - q_r),   J = J2(q_r),
    J^+ = J^T (J J^T)^-1 (7),   q_r <- q_r + dt dq_r,

with the section lengths of q_r clamped to the nominal [L0, max_extension L0].  The servo gets
(q_r, dq_r) (`Action.use_ref`) and the static feed-forward T2 = G2(q_r) + K2(q_r) (nominal gravity and
elasticity, `ctx.models.slave_static`).  u2 records (dq_r - dq_r_prev) / dt.  It needs a servo plant,
so it declares `actuations = ("servo",)`: on a torque plant the harness says so in one line before the run.

Parameters ([controller.params] or --set controller.params.KEY=VALUE):
    gain K (1/s), posture kq (1/s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.baselines import paper_master_law
from controllers.interface import (
    Action,
    Controller,
    ControllerContext,
    ControllerDiverged,
    Observation,
    check_range,
)

DET_MIN = 1e-14  # det(J J^T) at or below this: singular


class ResolvedRate(Controller):
    name = "resolved_rate"
    description = "resolved-rate control of the servo reference, J^+ with a posture term in the null space"
    actuations = ("servo",)

    @dataclass(frozen=True)
    class Params:
        gain: float = 20.0  # 1/s, K of the task-space error feedback
        posture: float = 1.0  # 1/s, kq of the null-space pull to the initial configuration

        def check(self) -> None:
            check_range("gain", self.gain, 0.0, 1e4, lo_open=True)
            check_range("posture", self.posture, 0.0, 1e3)

    def reset(self, ctx: ControllerContext) -> None:
        super().reset(ctx)
        self.q0 = ctx.q0[4:10].copy()
        self.qr = self.q0.copy()
        self.dqr = np.zeros(6)
        lo, hi = ctx.slave.length_range
        self.lo, self.hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        self.action.use_ref = True

    def step(self, obs: Observation) -> Action:
        ctx, a, p = self.ctx, self.action, self.ctx.params
        x1, dx1, _ = paper_master_law(ctx.models, ctx.gains, obs, a.T1)
        x2, J, _ = ctx.models.slave_kinematics(self.qr, self.dqr)
        A = J @ J.T
        if A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0] <= DET_MIN:
            raise ControllerDiverged("slave J2 J2^T singular at the reference", code=3)
        Jp = J.T @ np.linalg.inv(A)
        dq = Jp @ (dx1 + p.gain * (x1 - x2)) + (np.eye(6) - Jp @ J) @ (p.posture * (self.q0 - self.qr))
        a.u2[:] = (dq - self.dqr) / ctx.dt
        self.dqr[:] = dq
        self.qr += ctx.dt * dq
        np.clip(self.qr[0:3], self.lo, self.hi, out=self.qr[0:3])
        a.q2_ref[:] = self.qr
        a.dq2_ref[:] = dq
        a.T2[:] = ctx.models.slave_static(self.qr)
        a.use_ref = True
        return a
