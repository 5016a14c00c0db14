"""World geometry of both arms from a `Trajectory` (numpy, vectorized over steps).  Task [X, Z] of an arm
with base b is world (b_x + X, b_y, b_z + Z); world is MuJoCo's (right-handed, Z up).
"""

from __future__ import annotations

import warnings

import numpy as np

from harness.loop.trajectory import Trajectory

DEFAULT_MASTER_LENGTHS = (0.6, 0.6)  # m, paper Sec. VI (used only if traj.meta has no "master_lengths")
BACKBONE_POINTS_PER_SECTION = 10  # analytic backbone resolution when traj.meta has no "backbone"


def world_base(meta: dict, key: str) -> np.ndarray:
    b = meta.get(key)
    if b is None:
        return np.zeros(3)
    b = np.asarray(b, dtype=float).reshape(-1)
    if b.shape != (3,):
        raise ValueError(f"traj.meta[{key!r}] must be 3 numbers (world x, y, z), got shape {b.shape}")
    return b


def task_to_world(x: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Task-space [X, Z] (..., 2), relative to `base`, to world (..., 3): (b_x + X, b_y, b_z + Z)."""
    x = np.asarray(x, dtype=float)
    return np.stack([base[0] + x[..., 0], np.full(x.shape[:-1], base[1]), base[2] + x[..., 1]], axis=-1)


def master_points(q1: np.ndarray, lengths, base: np.ndarray) -> np.ndarray:
    """World positions (n, 3, 3) of master base, elbow, tip from q1 (n, 2) rad, angles from +Z towards +X:
    x1 = [l1 sin qa + l2 sin(qa + qb), l1 cos qa + l2 cos(qa + qb)] (controllers.params.MasterParams)."""
    q1 = np.asarray(q1, dtype=float).reshape(-1, 2)
    l1, l2 = (float(v) for v in np.asarray(lengths, dtype=float).reshape(2))
    a, ab = q1[:, 0], q1[:, 0] + q1[:, 1]
    elbow = np.stack([l1 * np.sin(a), l1 * np.cos(a)], axis=-1)
    tip = elbow + np.stack([l2 * np.sin(ab), l2 * np.cos(ab)], axis=-1)
    task = np.stack([np.zeros_like(elbow), elbow, tip], axis=1)  # (n, 3, 2)
    return task_to_world(task, base)


def cc_backbone(q2: np.ndarray, points_per_section: int = BACKBONE_POINTS_PER_SECTION) -> np.ndarray:
    """Constant-curvature backbone (n, 3 P + 1, 2) task space of q2 (n, 6) = [d (m), k (1/m)]: P points per
    section after the base (`controllers.cc.backbone_points`, compiled)."""
    from harness.loop.fast import K

    q2 = np.ascontiguousarray(q2, dtype=float).reshape(-1, 6)
    P = int(points_per_section)
    pts = np.empty((q2.shape[0], 3 * P + 1, 2))
    K.backbone_rows(q2, P, pts)
    return pts


def backbone_points_world(traj: Trajectory, slave_base: np.ndarray) -> np.ndarray | None:
    bb = traj.meta.get("backbone")
    if bb is not None:
        bb = np.asarray(bb, dtype=float)
        if bb.ndim != 3 or bb.shape[0] != len(traj) or bb.shape[2] != 3:
            warnings.warn(
                f"traj.meta['backbone'] has shape {bb.shape}, expected ({len(traj)}, P, 3); "
                "logging the analytic backbone of q2 instead", stacklevel=3)
        else:
            return bb
    return task_to_world(cc_backbone(traj.q2), slave_base)


def has_interaction(traj: Trajectory) -> bool:
    """Whether the run had interaction forces or contacts (then forces.png is written)."""
    if traj.F_true is None or not len(traj):
        return False
    return bool(np.any(traj.F_true != 0) or np.any(traj.F_sensed != 0)
                or (traj.contact is not None and np.any(traj.contact[:, 0] > 0)))
