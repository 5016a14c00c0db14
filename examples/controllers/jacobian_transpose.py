"""A complete user controller: Jacobian-transpose task-space PD with gravity compensation.

Run it on a torque plant: the analytic plant, or the MuJoCo plant with torque actuation and the
constant-curvature chain (torque mode diverges on the free chain with every controller tried):
    teleop run --controller examples/controllers/jacobian_transpose.py:JacobianTransposePD \
        --plant analytic --duration 5
    teleop check --controller examples/controllers/jacobian_transpose.py:JacobianTransposePD \
        --actuation torque --set plant.enforce_cc=true --duration 5 \
        --bounds examples/controllers/jacobian_transpose_bounds.toml
On the default plant (MuJoCo, servo) use examples/controllers/resolved_rate.py.

Master: the paper's law (12)-(13) (the master stands for the operator's arm tracking x_d (40)).
Slave (6 joints, 2 task coordinates): the tip is pulled toward the master tip by a task-space spring
and damper mapped through J2^T, the nominal static forces are cancelled, and the self-motion is damped
in joint space, mass-weighted (Takegaki & Arimoto 1981; Khatib 1987 for the redundant case):

    T2 = J2^T (Kp e2 + Kd de2) + G2(q2) + K2(q2) + (I - J2^T J2^+T) tau0,
    tau0 = M2 (-c dq2 - kq (q2 - q2(0))),
    e2 = x1 - x2 (16), de2 = dx1 - J2 dq2, J2^+ = J2^T (J2 J2^T)^-1 (7),

G2 + K2 = the nominal gravity and elastic forces (`ctx.models.slave_static`).  With exact
compensation the closed loop is passive and the regulation error goes to zero for a constant x1
(Lyapunov function 1/2 dq2^T M2 dq2 + 1/2 Kp |e2|^2; the damping terms only dissipate).  The
self-motion damping is mass-weighted (c M2 dq2) because the joint inertias span five decades (M2
eigenvalues 4e-5 to 2 in SI units at the paper's start): a plain diagonal damping would be
unstable at the 1 ms control period.  The posture term kq pulls the self-motion back to the initial
configuration through the null-space projector I - J2^T J2^+T (which leaves the tip force unchanged);
without it the self-motion drifts to the curvature limits within 5 s on some noise seeds.
T2 is what a torque plant needs (MuJoCo
`plant.actuation = "torque"`, the analytic plant); it does not provide a servo reference, so it
declares `actuations = ("torque",)`, `plants = ("mujoco", "analytic")` and, on MuJoCo, the
constant-curvature chain (`requires`); anything else is refused before the run.

Parameters ([controller.params] or --set controller.params.KEY=VALUE):
    kp (N/m), kd (N s/m), joint_damping c (1/s), posture kq (1/s^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.baselines import paper_master_law
from controllers.interface import Action, Controller, ControllerDiverged, Observation, check_range


class JacobianTransposePD(Controller):
    name = "jacobian_transpose"
    description = "Jacobian-transpose task-space PD with gravity/elastic compensation (torque plants)"
    actuations = ("torque",)
    plants = ("mujoco", "analytic")  # on the rod its stiff gains blow up within 10 ms
    requires = {"mujoco": {"plant.enforce_cc": True}}  # the free chain diverges under torque (docs)

    @dataclass(frozen=True)
    class Params:
        kp: float = 400.0  # N/m, task-space stiffness
        kd: float = 40.0  # N s/m, task-space damping
        joint_damping: float = 5.0  # 1/s, c of the mass-weighted joint damping c M2 dq2
        posture: float = 25.0  # 1/s^2, kq of the null-space posture term

        def check(self) -> None:
            check_range("kp", self.kp, 0.0, 1e6, lo_open=True)
            check_range("kd", self.kd, 0.0, 1e5)
            check_range("joint_damping", self.joint_damping, 0.0, 1e4)
            check_range("posture", self.posture, 0.0, 1e6)

    def step(self, obs: Observation) -> Action:
        ctx, a, p = self.ctx, self.action, self.ctx.params
        x1, dx1, _ = paper_master_law(ctx.models, ctx.gains, obs, a.T1)
        x2, J2, _ = ctx.models.slave_kinematics(obs.q2, obs.dq2)
        f = p.kp * (x1 - x2) + p.kd * (dx1 - J2 @ obs.dq2)  # task-space force at the tip, N
        A = J2 @ J2.T
        if A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0] <= 1e-14:
            raise ControllerDiverged("slave J2 J2^T singular", code=3)
        Jp = J2.T @ np.linalg.inv(A)  # (7)
        M2, _ = ctx.models.slave_dynamics(obs.q2, obs.dq2)
        tau0 = M2 @ (-p.joint_damping * obs.dq2 - p.posture * (obs.q2 - ctx.q0[4:10]))
        a.T2[:] = J2.T @ f + tau0 - J2.T @ (Jp.T @ tau0)
        a.T2 += ctx.models.slave_static(obs.q2)
        return a
