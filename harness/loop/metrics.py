"""Summary metrics of a run (bounds files, sweeps, `metrics.json`): Euclidean norms of the task-space
errors (m) after `scn.transient` s, RMS = sqrt(mean |e|^2) and max; NaN (JSON null) after the transient
for a run that stopped before it."""

from __future__ import annotations

import math

import numpy as np

from harness.config.scenario import Scenario
from harness.loop.trajectory import Trajectory


def _rms_max(e: np.ndarray | None, mask: np.ndarray) -> tuple[float, float]:
    if e is None or not mask.any():
        return math.nan, math.nan
    with np.errstate(over="ignore", invalid="ignore"):  # a diverged run may overflow: inf, not a warning
        n = np.linalg.norm(e[mask], axis=1)
        return float(np.sqrt(np.mean(n * n))), float(n.max())


def contact_metrics(traj: Trajectory, scn: Scenario, mask: np.ndarray) -> dict:
    """contact_force_peak (max |true F2|, N), contact_force_rms (after the transient, N), penetration_max
    (any arm geom into any object, m), contact_time / body_contact_time (s with an arm contact / one away
    from the tip body), force_tracking_rms (|sensed F2 - true F2| after the transient, N)."""
    n = len(traj)
    if not n or traj.F_true is None:
        return {k: math.nan for k in ("contact_force_peak", "contact_force_rms", "penetration_max",
                                      "contact_time", "body_contact_time", "force_tracking_rms")}
    with np.errstate(over="ignore", invalid="ignore"):
        f2 = np.linalg.norm(traj.F_true[:, 2:4], axis=1)
        rms, _ = _rms_max(traj.F_true[:, 2:4], mask)
        ftr, _ = _rms_max(traj.F_sensed[:, 2:4] - traj.F_true[:, 2:4], mask)
    c = traj.contact
    return {
        "contact_force_peak": float(f2.max()), "contact_force_rms": rms,
        "penetration_max": float(max(0.0, -c[:, 3].min())),
        "contact_time": float((c[:, 0] > 0).sum() * scn.control_dt),
        "body_contact_time": float((c[:, 0] > c[:, 4]).sum() * scn.control_dt),
        "force_tracking_rms": ftr,
    }


def compute_metrics(traj: Trajectory, scn: Scenario) -> dict:
    """Metrics dict: e1_rms, e1_max, e2_rms, e2_max, e2_plant_rms, e2_plant_max (MuJoCo tip; NaN on
    the analytic plant), deN_rms (null-space velocity error (23), mixed units), beta_min, ya_max,
    e1_final, e2_final, range_violation (max excursion of section lengths / bending angles outside
    their allowed range, m or rad; 0 when inside), mujoco_warnings, status, message,
    sim_time_reached, wall_time, realtime_factor."""
    n = len(traj)
    mask = traj.t >= scn.transient if n else np.zeros(0, bool)
    e1_rms, e1_max = _rms_max(traj.e1, mask)
    e2_rms, e2_max = _rms_max(traj.e2, mask)
    e2p_rms, e2p_max = _rms_max(traj.e2_plant, mask)
    deN_rms, _ = _rms_max(traj.deN, mask)
    if n:
        lo, hi = scn.slave.length_range
        d, th = traj.q2[:, :3], traj.q2[:, 3:] * traj.q2[:, :3]
        viol = max(float(np.max(lo - d)), float(np.max(d - hi)),
                   float(np.max(np.abs(th) - scn.slave.max_bend)), 0.0)
    else:
        viol = math.nan
    contact = contact_metrics(traj, scn, mask)
    t_end = float(traj.t[-1] + scn.control_dt) if n else 0.0
    wall = float(traj.meta.get("wall_time", math.nan))
    return {
        "e1_rms": e1_rms, "e1_max": e1_max, "e2_rms": e2_rms, "e2_max": e2_max,
        "e2_plant_rms": e2p_rms, "e2_plant_max": e2p_max, "deN_rms": deN_rms,
        "beta_min": float(traj.beta.min()) if n else math.nan,
        "ya_max": float(traj.ya.max()) if n else math.nan,
        "e1_final": float(np.linalg.norm(traj.e1[-1])) if n else math.nan,
        "e2_final": float(np.linalg.norm(traj.e2[-1])) if n else math.nan,
        "range_violation": viol,
        **contact,
        "mujoco_warnings": int(traj.meta.get("mujoco_warnings", 0)),
        "status": traj.status, "message": traj.message,
        "sim_time_reached": t_end, "wall_time": wall,
        "realtime_factor": (t_end / wall) if wall and wall > 0 and not math.isnan(wall) else math.nan,
    }
