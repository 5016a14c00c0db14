"""Environment objects, contact sensing and the t = 0 clearance check of the MuJoCo plant
(docs/guide/contact.md): frictionless pairs with solref = (-k (1 - d) A_b, -c (1 - d) A_b),
solimp = (d, d, 0.001, 0.5, 2), i.e. f = k r + c dr/dt (A_b = body_invweight0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from harness.config.scenario import EnvironmentConfig, EnvObject

IMPEDANCE = 0.9  # solimp d (constant over the penetration)
BOX_DEPTH = 0.15  # m, y half size of box obstacles
TIP_RADIUS_FACTOR = 1.25  # tip sphere radius / segment capsule radius
N_POINTS = 4  # contact points recorded per control step (largest forces)
# contact sensor data bits (mjtConDataField order) and reductions
_FOUND, _FORCE, _DIST, _POS, _NORMAL = 1, 2, 8, 16, 32
_MINDIST, _MAXFORCE, _NETFORCE = 1, 2, 3
SENSORS = ("tip_contact_net", "arm_contact_net", "arm_contact_min", "arm_contact_pts")


@dataclass(frozen=True)
class ContactMap:
    """d.sensordata addresses adr (4,) int64 [tip net, arm net, arm mindist, arm points], the object and
    arm geom ids and the tip body id."""

    adr: np.ndarray
    object_geoms: np.ndarray
    arm_geoms: np.ndarray
    tip_body: int
    n_points: int = N_POINTS


def contact_parameters(obj: EnvObject, invweight: float, d: float = IMPEDANCE) -> tuple[list, list]:
    """solref, solimp of a pair (arm body with translational inverse weight `invweight` [1/kg], obj)."""
    k = obj.stiffness
    c = 2.0 * obj.damping_ratio * math.sqrt(k / invweight)
    return [-k * (1.0 - d) * invweight, -c * (1.0 - d) * invweight], [d, d, 0.001, 0.5, 2.0]


def _quat_y(theta: float) -> list[float]:
    return [math.cos(0.5 * theta), 0.0, math.sin(0.5 * theta), 0.0]


def _add_object(spec: mujoco.MjSpec, obj: EnvObject, base: np.ndarray) -> str:
    name = f"env_{obj.name}_geom"
    if obj.kind == "plane":
        kw = dict(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.4, BOX_DEPTH, 0.02],
                  quat=_quat_y(math.atan2(*obj.normal)), rgba=[0.55, 0.55, 0.6, 0.5])
    elif obj.kind == "box":
        kw = dict(type=mujoco.mjtGeom.mjGEOM_BOX, size=[obj.size[0], BOX_DEPTH, obj.size[1]],
                  quat=_quat_y(obj.angle), rgba=[0.3, 0.6, 0.4, 0.6])
    else:
        kw = dict(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[obj.size[0], 0.0, 0.0], rgba=[0.3, 0.6, 0.4, 0.6])
    spec.worldbody.add_geom(name=name, pos=[base[0] + obj.position[0], base[1], base[2] + obj.position[1]],
                            contype=0, conaffinity=0, condim=1, density=0.0, **kw)
    return name


def add_environment(spec: mujoco.MjSpec, env: EnvironmentConfig, invweight: dict[str, float],
                    arm_geoms: list[tuple[str, str]]) -> None:
    """Add the objects, the tip sphere, one pair per (arm geom, object) and the contact sensors to `spec`
    and enable contacts.  invweight: body name -> body_invweight0[b, 0] of the model without the
    environment; arm_geoms: (geom name, body name) of the segment capsules."""
    base = np.asarray(spec.body("octarm_base").pos, dtype=float)
    tip = spec.body("octarm_tip_body")
    r = float(spec.geom(arm_geoms[0][0]).size[0])
    tip.add_geom(name="octarm_tip_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                 size=[TIP_RADIUS_FACTOR * r, 0, 0], contype=0, conaffinity=0, density=0.0, group=2,
                 rgba=[0.9, 0.2, 0.2, 1.0])
    geoms = list(arm_geoms) + [("octarm_tip_geom", "octarm_tip_body")]
    for obj in env.objects:
        oname = _add_object(spec, obj, base)
        for gname, bname in geoms:
            solref, solimp = contact_parameters(obj, invweight[bname])
            spec.add_pair(name=f"pair_{gname}_{obj.name}", geomname1=gname, geomname2=oname, condim=1,
                          solref=solref, solimp=solimp, margin=0.0, gap=0.0)
    body, xbody, first = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_XBODY, arm_geoms[0][1]
    for name, objtype, objname, data, reduce, num in (  # the sensors of ContactMap.adr, in its order
            (SENSORS[0], body, "octarm_tip_body", _FOUND | _FORCE, _NETFORCE, 1),
            (SENSORS[1], xbody, first, _FOUND | _FORCE, _NETFORCE, 1),
            (SENSORS[2], xbody, first, _FOUND | _DIST, _MINDIST, 1),
            (SENSORS[3], xbody, first, _FOUND | _FORCE | _POS | _NORMAL, _MAXFORCE, N_POINTS)):
        s = spec.add_sensor(name=name, type=mujoco.mjtSensor.mjSENS_CONTACT, objtype=objtype, objname=objname)
        s.intprm[:3] = [data, reduce, num]
    spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)


def contact_map(m: mujoco.MjModel) -> ContactMap:
    adr = np.array([m.sensor_adr[m.sensor(n).id] for n in SENSORS], dtype=np.int64)
    obj = [g for g in range(m.ngeom) if m.geom(g).name.startswith("env_")]
    paired = {int(m.pair_geom1[p]) for p in range(m.npair)} | {int(m.pair_geom2[p]) for p in range(m.npair)}
    arm = sorted(paired - set(obj))  # MuJoCo may store either geom of a pair first
    return ContactMap(adr=adr, object_geoms=np.array(obj, dtype=np.int64), arm_geoms=np.array(arm, np.int64),
                      tip_body=int(m.body("octarm_tip_body").id))


def clearance(m: mujoco.MjModel, d: mujoco.MjData, cm: ContactMap) -> list[tuple[int, int, float]]:
    """(object geom, arm geom, signed distance m) of every penetrating pair (mj_geomDistance; after
    mj_forward)."""
    out = []
    fromto = np.zeros(6)
    for g2 in cm.object_geoms:
        for g1 in cm.arm_geoms:
            dist = mujoco.mj_geomDistance(m, d, int(g1), int(g2), 0.05, fromto)
            if dist < 0.0:
                out.append((int(g2), int(g1), float(dist)))
    return out
