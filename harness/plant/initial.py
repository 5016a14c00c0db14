"""The closed loop's initial state (both arms at rest) from the scenario alone (the loops, and the MuJoCo
plant's t = 0 clearance check)."""

from __future__ import annotations

import numpy as np

from controllers import master as master_model
from controllers import slave as slave_model
from harness.config.scenario import Scenario


class InitialStateError(ValueError):
    """The scenario's initial state is impossible (one line, naming the field)."""


def initial_state(scn: Scenario) -> np.ndarray:
    """[q1, dq1, q2, dq2] (16,) at t = 0, at rest: master IK of x_d(0) (40) + initial.master_offset;
    slave initial.slave_q2, or equal sections of initial.slave_curvature, tip at the master tip's Z."""
    tr = scn.trajectory
    xd0 = np.array([tr.center[0], tr.center[1] + tr.amplitude[1]])
    x0 = xd0 + np.asarray(scn.initial.master_offset, dtype=float)
    pm = scn.plant_master
    try:
        q1 = master_model.ik(pm, x0, scn.initial.master_elbow)
    except ValueError as exc:
        raise InitialStateError(f"initial.master_offset: {exc}") from None
    x1 = master_model.fk(pm, q1)
    ps = scn.plant_slave
    if scn.initial.slave_q2 is not None:
        q2 = np.asarray(scn.initial.slave_q2, dtype=float)
    else:
        kappa = scn.initial.slave_curvature
        d = float(np.mean(ps.rest_lengths))
        for _ in range(50):
            q2 = np.array([d, d, d, kappa, kappa, kappa])
            z = slave_model.tip_position(ps, q2)[1]
            dz = slave_model.jacobian(ps, q2)[1, :3].sum()
            step = (x1[1] - z) / dz
            d += step
            if abs(step) < 1e-14:
                break
        q2 = np.array([d, d, d, kappa, kappa, kappa])
        lo, hi = ps.length_range
        if np.any(q2[:3] < lo - 1e-12) or np.any(q2[:3] > hi + 1e-12):
            raise InitialStateError(
                f"trajectory.center: the slave cannot start under the master tip (Z = {x1[1]:.3f} m "
                f"needs section lengths {d:.3f} m outside [{lo.min():.3f}, {hi.max():.3f}] m)")
    return np.concatenate([q1, np.zeros(2), q2, np.zeros(6)])
