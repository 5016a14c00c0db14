"""World geometry of both arms from a `Trajectory` (vectorized over steps) and of the environment's objects
(`asdict` of `harness.config.scenario.EnvObject`, slave task frame), numpy only.  Task [X, Z] of an arm with
base b is world (b_x + X, b_y, b_z + Z); world is MuJoCo's (right-handed, Z up)."""

from __future__ import annotations

import numpy as np

from harness.loop.trajectory import Trajectory

DEFAULT_MASTER_LENGTHS = (0.6, 0.6)  # m, paper Sec. VI (used only if traj.meta has no "master_lengths")
BACKBONE_POINTS_PER_SECTION = 10  # analytic backbone resolution when traj.meta has no "backbone"
OBSTACLE_HALF_DEPTH = 0.15  # m, half extent along world Y of an obstacle drawn in the 3-D view
PLANE_HALF_LENGTH = 0.8  # m, drawn extent of a plane (a wall) either side of its `position`
PLANE_THICKNESS = 0.02  # m, a plane is drawn as a slab this thick on its solid side


def world_base(meta: dict, key: str) -> np.ndarray:
    """World position (3,) of an arm's base, meta[key] (absent: the origin)."""
    b = meta.get(key)
    return np.zeros(3) if b is None else np.asarray(b, dtype=float).reshape(3)


def task_to_world(x: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Task-space [X, Z] (..., 2), relative to `base`, to world (..., 3): (b_x + X, b_y, b_z + Z)."""
    x = np.asarray(x, dtype=float)
    return np.stack([base[0] + x[..., 0], np.full(x.shape[:-1], base[1]), base[2] + x[..., 1]], axis=-1)


def master_points(traj: Trajectory, base: np.ndarray) -> np.ndarray:
    """World positions (n, 3, 3) of master base, elbow, tip: traj.master_pos, else from q1 (n, 2) rad, angles
    from +Z towards +X: x1 = [l1 sin qa + l2 sin(qa + qb), l1 cos qa + l2 cos(qa + qb)] (l: meta's)."""
    if traj.master_pos is not None:
        return np.asarray(traj.master_pos, dtype=float).reshape(-1, 3, 3)
    q1 = np.asarray(traj.q1, dtype=float).reshape(-1, 2)
    lengths = (traj.meta or {}).get("master_lengths", DEFAULT_MASTER_LENGTHS)
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


def backbone_points_world(traj: Trajectory, slave_base: np.ndarray) -> np.ndarray:
    """World backbone (n, P, 3): meta["backbone"] (the MuJoCo loop's, of the sensed q2), else the CC one."""
    bb = traj.meta.get("backbone")
    return np.asarray(bb, dtype=float) if bb is not None else task_to_world(cc_backbone(traj.q2), slave_base)


def has_interaction(traj: Trajectory) -> bool:
    """Whether the run had interaction forces or contacts (then forces.png is written)."""
    if traj.F_true is None or not len(traj):
        return False
    return bool(np.any(traj.F_true != 0) or np.any(traj.F_sensed != 0)
                or (traj.contact is not None and np.any(traj.contact[:, 0] > 0)))


def _rot_y(u: np.ndarray, w: np.ndarray, angle: float) -> np.ndarray:
    """Local (u, w) of a shape rotated by `angle` about +y (MuJoCo's convention) to task [X, Z]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([u * c + w * s, -u * s + w * c], axis=-1)


def obstacle_solid(ob: dict) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A plane or box obstacle as a box: (centre [X, Z] task (2,), half sizes (3,) (local x, y, z),
    rotation about +y (rad)); None for a sphere.  A plane is a slab PLANE_THICKNESS thick on its solid
    side, 2 PLANE_HALF_LENGTH long."""
    p = np.asarray(ob["position"], dtype=float)
    if ob["kind"] == "plane":
        n = np.asarray(ob["normal"], dtype=float)
        n = n / max(float(np.linalg.norm(n)), 1e-12)
        angle = float(np.arctan2(n[0], n[1]))  # local +z along the normal (as the MuJoCo plane geom)
        return (p - 0.5 * PLANE_THICKNESS * n,
                np.array([PLANE_HALF_LENGTH, OBSTACLE_HALF_DEPTH, 0.5 * PLANE_THICKNESS]), angle)
    if ob["kind"] == "box":
        sx, sz = ob["size"]
        return p, np.array([sx, OBSTACLE_HALF_DEPTH, sz]), float(ob["angle"])
    return None


def obstacle_outline(ob: dict, points: int = 64) -> np.ndarray:
    """Closed outline (P, 2) of an obstacle in the slave's task frame [X, Z] (m): the slab of a plane,
    the rectangle of a box, the circle of a sphere."""
    solid = obstacle_solid(ob)
    if solid is None:
        r = float(ob["size"][0])
        a = np.linspace(0.0, 2.0 * np.pi, points + 1)
        return np.asarray(ob["position"], dtype=float) + r * np.stack([np.cos(a), np.sin(a)], axis=-1)
    c, half, angle = solid
    u = np.array([-1.0, 1.0, 1.0, -1.0, -1.0]) * half[0]
    w = np.array([-1.0, -1.0, 1.0, 1.0, -1.0]) * half[2]
    return c + _rot_y(u, w, angle)


def obstacle_face(ob: dict) -> np.ndarray:
    """What the 2-D views draw of an obstacle, (P, 2) task [X, Z]: the surface line of a plane (the side
    the arm touches, 2 PLANE_HALF_LENGTH long), the closed outline of a box or sphere."""
    if ob["kind"] != "plane":
        return obstacle_outline(ob)
    p = np.asarray(ob["position"], dtype=float)
    n = np.asarray(ob["normal"], dtype=float)
    n = n / max(float(np.linalg.norm(n)), 1e-12)
    t = np.array([-n[1], n[0]])
    return np.stack([p - PLANE_HALF_LENGTH * t, p + PLANE_HALF_LENGTH * t])
