"""Environment objects on the Cosserat plant: the `[environment.objects.<name>]` of the scenario acting on
every node of the rod (`harness.plant.cosserat.plant`), through the penalty law of PyElastica's
`RodPlaneContact` / `RodSphereContact` compiled into the rod's own step
(`harness.plant.cosserat.kernels.contact_forces`).

Geometry (slave task frame [X, Z], base at the origin, as `EnvObject.position`).  Each node j >= 1 of the
centreline is a ball of radius `NODE_RADIUS` (= the MuJoCo plant's segment capsule radius, 0.02 m), so
contact can happen anywhere along the body.  `plane`: the wall through `position` with unit `normal`
toward the free side; `sphere`: centre `position`, radius size[0].  `box`: not supported (PyElastica 1.0
has rod-plane, rod-sphere, rod-cylinder and rod-rod contact only, no box): ConfigError.

Law (frictionless; PyElastica's normal spring-damper, evaluated per node): penetration g_j > 0 of node j
gives the force (k g_j - c_j n . v_j) n on that node (n the object's outward normal at the node), with
k = `stiffness` (N/m) per node and c_j = 2 `damping_ratio` sqrt(k m_j), m_j the node's mass.  A static
push carried by one node (the tip against a plane or a sphere) therefore gives F = k g, as the MuJoCo
plant's contact (harness.plant.environment); when several nodes touch, the total is k times the sum of
their penetrations (a contact stiffness per node, not per unit length).  Differences from PyElastica's
classes: the law is evaluated at the nodes instead of the element centres (PyElastica's plane check at
element centres misses a tip pushed head-on into a wall by half an element), PyElastica's extra plane
"response force" (which cancels the normal part of the rod's own load and so makes the static
penetration zero, not F / k) is not applied, and there is no friction.  As in PyElastica the force is
not clamped at 0 (a fast separation can pull briefly).

Sensing: F2 = the contact force ON the tip node (`tip_force`), N, slave frame; the summary `summary`
has the record's `contact` layout [nodes in contact, net contact force on the rod X, Z (N), min signed
distance node-object (m, < 0 = penetration; 0 without objects), tip node in contact (0/1)].
"""

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
