"""Environment objects on the Cosserat plant: plane / sphere penalty contact on every rod node
(`kernels.contact_forces`); docs/plants.md, "Contact on the rod"."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from harness.config.errors import ConfigError
from harness.config.scenario import EnvironmentConfig

NODE_RADIUS = 0.02  # m, contact radius of every rod node (MuJoCo plant: segment capsule radius)
PLANE, SPHERE = 0.0, 1.0


def contact_arrays(env: EnvironmentConfig, node_mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(objs (no, 6), cdamp (no, nn + 1)) for `kernels.contact_forces`; node_mass (nn,) kg.
    ConfigError naming a box object (not supported on the Cosserat plant)."""
    objs = np.zeros((len(env.objects), 6))
    cdamp = np.zeros((len(env.objects), node_mass.shape[0] + 1))
    for i, o in enumerate(env.objects):
        if o.kind == "box":
            raise ConfigError(f"environment.objects.{o.name}.kind = 'box': the Cosserat plant supports plane "
                              "and sphere (PyElastica has no box contact)",
                              path=f"environment.objects.{o.name}.kind", value="box")
        if o.kind == "plane":
            nx, nz = o.normal
            nrm = math.hypot(nx, nz)
            objs[i] = (PLANE, o.position[0], o.position[1], nx / nrm, nz / nrm, NODE_RADIUS)
        else:
            objs[i] = (SPHERE, o.position[0], o.position[1], 0.0, 0.0, o.size[0] + NODE_RADIUS)
        cdamp[i, 0] = o.stiffness
        cdamp[i, 1:] = 2.0 * o.damping_ratio * np.sqrt(o.stiffness * node_mass)
    return objs, cdamp


@njit(cache=True)
def signed_distance(pos, objs, out):
    """Signed distance (m) of nodes 1.. (pos (3, nn)) to each object, minimum over objects, into out (nn,)
    (< 0 = penetration; out[0] = +inf, the clamped base)."""
    nn = pos.shape[1]
    out[0] = np.inf
    for j in range(1, nn):
        best = np.inf
        for o in range(objs.shape[0]):
            dx = pos[0, j] - objs[o, 1]
            dz = pos[2, j] - objs[o, 2]
            if objs[o, 0] == 0.0:
                g = objs[o, 3] * dx + objs[o, 4] * dz - objs[o, 5]
            else:
                g = math.sqrt(dx * dx + dz * dz) - objs[o, 5]
            best = min(best, g)
        out[j] = best


def check_clearance(env: EnvironmentConfig, objs: np.ndarray, pos: np.ndarray) -> None:
    """ConfigError naming the object that intersects the rod's centreline pos (3, nn) at t = 0."""
    d = np.empty(pos.shape[1])
    for i, o in enumerate(env.objects):
        signed_distance(pos, objs[i:i + 1], d)
        j = int(np.argmin(d))
        if d[j] < 0.0:
            raise ConfigError(f"environment.objects.{o.name}: intersects the slave at t = 0 (rod node {j} "
                              f"penetrates {-d[j]:.4g} m); move the object or the initial state",
                              path=f"environment.objects.{o.name}")


def summary(f_contact: np.ndarray, pos: np.ndarray, objs: np.ndarray, dist: np.ndarray,
            out: np.ndarray) -> None:
    """The record's contact row (5,) from the nodal contact forces f_contact (3, nn) (N, last substep),
    the nodes pos (3, nn) and a scratch dist (nn,)."""
    out[:] = 0.0
    if objs.shape[0] == 0:
        return
    signed_distance(pos, objs, dist)
    touching = np.abs(f_contact[0]) + np.abs(f_contact[2]) > 0.0
    out[0] = float(np.count_nonzero(touching))
    out[1] = float(f_contact[0].sum())
    out[2] = float(f_contact[2].sum())
    out[3] = min(float(dist.min()), 0.0)
    out[4] = 1.0 if touching[-1] else 0.0
