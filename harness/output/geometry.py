"""World geometry of both arms from a `Trajectory` (numpy only, vectorized over steps; no Rerun or
matplotlib): bases, task space -> world, master link points, the analytic constant-curvature backbone.
Task-space [X, Z] of a robot with base b maps to world (b_x + X, b_y, b_z + Z); world is right-handed,
Z up, like MuJoCo.
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
    out = np.empty(x.shape[:-1] + (3,))
    out[..., 0] = base[0] + x[..., 0]
    out[..., 1] = base[1]
    out[..., 2] = base[2] + x[..., 1]
    return out


def master_points(q1: np.ndarray, lengths, base: np.ndarray) -> np.ndarray:
    """World positions of master base, elbow, tip, (n, 3, 3), from joint angles q1 (n, 2).

    Angles from +Z towards +X (controllers.params.MasterParams):
    x1 = [l1 sin qa + l2 sin(qa + qb), l1 cos qa + l2 cos(qa + qb)].
    """
    q1 = np.asarray(q1, dtype=float).reshape(-1, 2)
    l1, l2 = (float(v) for v in np.asarray(lengths, dtype=float).reshape(2))
    a, ab = q1[:, 0], q1[:, 0] + q1[:, 1]
    elbow = np.stack([l1 * np.sin(a), l1 * np.cos(a)], axis=-1)
    tip = elbow + np.stack([l2 * np.sin(ab), l2 * np.cos(ab)], axis=-1)
    task = np.stack([np.zeros_like(elbow), elbow, tip], axis=1)  # (n, 3, 2)
    return task_to_world(task, base)


def cc_backbone(q2: np.ndarray, points_per_section: int = BACKBONE_POINTS_PER_SECTION) -> np.ndarray:
    """Planar constant-curvature backbone of q2 = [d1, d2, d3, k1, k2, k3], task space (n, 3 P + 1, 2).

    Base at the origin, tangent +Z, k > 0 bends toward +X (controllers.params.SlaveParams).  Along a
    section with tangent angle phi (from +Z toward +X) and arc s: p(s) = p0 + t sin(k s)/k
    + nrm (1 - cos(k s))/k with t = (sin phi, cos phi), nrm = (cos phi, -sin phi); phi += k d.
    Near-zero curvature uses the series limits (s, k s^2 / 2), so k = 0 is exact.
    """
    q2 = np.asarray(q2, dtype=float).reshape(-1, 6)
    n, P = q2.shape[0], int(points_per_section)
    u = np.linspace(0.0, 1.0, P + 1)[1:]  # fraction of the section, (P,)
    pts = np.empty((n, 3 * P + 1, 2))
    pts[:, 0] = 0.0
    p0 = np.zeros((n, 2))
    phi = np.zeros(n)
    for i in range(3):
        d, k = q2[:, i], q2[:, 3 + i]
        s = d[:, None] * u[None, :]  # (n, P)
        ks = k[:, None] * s
        small = np.abs(ks) < 1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            along = np.where(small, s * (1.0 - ks * ks / 6.0), np.sin(ks) / k[:, None])
            across = np.where(small, 0.5 * ks * s, (1.0 - np.cos(ks)) / k[:, None])
        t = np.stack([np.sin(phi), np.cos(phi)], axis=-1)[:, None, :]
        nrm = np.stack([np.cos(phi), -np.sin(phi)], axis=-1)[:, None, :]
        seg = p0[:, None, :] + t * along[..., None] + nrm * across[..., None]
        pts[:, 1 + i * P: 1 + (i + 1) * P] = seg
        p0 = seg[:, -1]
        phi = phi + k * d
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
