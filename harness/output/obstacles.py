"""The environment's objects as drawn (numpy only): each of `traj.meta["environment"]` (`asdict` of a
`harness.config.scenario.EnvObject`; position [X, Z], normal in the slave's task frame) as a solid for the
3-D view and an outline in the task plane for the 2-D view and the figures.
"""

from __future__ import annotations

import numpy as np

OBSTACLE_HALF_DEPTH = 0.15  # m, half extent along world Y of an obstacle drawn in the 3-D view
PLANE_HALF_LENGTH = 0.8  # m, drawn extent of a plane (a wall) either side of its `position`
PLANE_THICKNESS = 0.02  # m, a plane is drawn as a slab this thick on its solid side


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
