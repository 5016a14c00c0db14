"""MuJoCo "true plant": master + discretized Octarm built from the MJCF in ``mjcf/`` by editing an MjSpec.

Frames and units
----------------
SI units (m, kg, s, rad).  Both robots move in planes parallel to the world x-z plane; hinges turn about
+y (a positive angle takes +z toward +x).  Each robot's task space [X, Z] is relative to its own base:
``master_base`` at world (0, -0.3, 0) and ``octarm_base`` at world (0, +0.3, 0).

Octarm discretization ("hinges at segment midpoints", second order)
--------------------------------------------------------------------
Section i (0..2) with current arc length d_i, curvature k_i, bend Theta_i = k_i d_i and rest length L0_i is
split into N segments of current length l_i = d_i / N (rest l0_i = L0_i / N).  Body
``octarm_s{i}_seg{j}_body`` sits at the MIDPOINT of segment j; its joints are, in order,

* slide ``octarm_s{i}_seg{j}_slide`` along the parent's tangent (the body z before the hinge): the
  extension of the rod from the previous node (midpoint, or the base) to this one;
* hinge ``octarm_s{i}_seg{j}_hinge`` about +y: the bend Theta_i / N of one segment.

Body positions relative to the parent are the rest rod lengths: l0_0 / 2 for the very first body,
(l0_{i-1} + l0_i) / 2 for j = 0 and i >= 1, l0_i otherwise.  After the last segment, ``octarm_tip_body``
at l0_2 / 2 with one slide ``octarm_tip_slide`` carries ``octarm_tip_site``.

On the constant-curvature (CC) manifold, with e_i = d_i - L0_i, the chain joints are
  hinge(i, j) = Theta_i / N,     slide(i, j >= 1) = e_i / N,
  slide(i, 0) = (e_{i-1} + e_i) / (2N)  (drop e_{-1}),     tip slide = e_2 / (2N),
i.e. joints = C u with u = [e_0, e_1, e_2, Theta_0, Theta_1, Theta_2] and a constant C (n_chain, 6).
The rod from node j-1 to node j points along the tangent at the arc point halfway between the two
midpoints (midpoint rule on the tangent; one-sided half rods at the base, section boundaries and tip):
node positions approximate the arc midpoints to O(1/N^2) and the final orientation is exact.

Chain joint order (``ChainMap.chain_*`` arrays, "qpos_chain"): the MuJoCo order, i.e. for each section,
for each segment, slide then hinge; the tip slide last.  n_chain = 6 N + 1.

Mass: segment (i, j) is a point-like mass m_i / N at its body origin (the segment midpoint) with rod
inertia about y (m_i / N) l0_i^2 / 12 plus the slice inertia (see ``chain_params.segment_inertias``:
trapezoidal split over the two rod orientations bounding the segment, which keeps the slice term second order;
putting all of it on the segment's own body would be first order, because the body frame carries the
tangent at the segment END).  The tip body needs a mass for MuJoCo: ``TIP_MASS_FRACTION * m_2 / N``,
taken from the last segment so that the total mass is exact (a modelled mismatch of O(1e-3 / N^2)).

Elasticity: MuJoCo joint springs (hinge N Kb_i / L0_i; slide N Ke_i inside a section, series
combinations for the half/boundary rods) plus ``chain_elastic_correction`` (applied by the harness
through qfrc_applied at every physics step) give -grad of the exact discrete energy, equal to the
analytic elastic force on the CC manifold.  Without the correction the springs alone are exact only
at rest length with equal neighbouring extensions.  Viscous damping of SlaveParams (on q2 rates) plus
the rod's material damping (``plant.bending_viscosity`` eta_b -> hinge eta_b / h,
``plant.extension_viscosity`` eta_a -> slide eta_a / h, h the segment length) is MuJoCo joint damping
(``chain_params.joint_damping``, integrated implicitly; exact at rest length on the manifold).

Actuation, each defined per unit length of the section (so the chain has a continuum limit in N):
``servo``: a position actuator per chain joint (force kp (ctrl - q) - kv qdot, ctrl = the joint target,
e.g. ``joints_from_q2``; fold (kv / kp) qdot_ref into it for velocity tracking), gains from
``chain_params.servo_gains``: each section's CC coordinate (e_i, Theta_i), moved alone, is a servo of
``servo_frequency`` and ``servo_damping_ratio`` against its inertia diag(C^T M C) at the straight rest
configuration, spread over the joints like the springs.  ``torque``: a motor per chain joint (gear 1),
driven by the virtual-work map ``chain_force_from_T2``.  ``muscle``: per section two one-sided groups of
extensor muscles at lateral offsets s = +r, -r (``plant.muscle_radius``), each a fixed tendon
``octarm_s{i}_muscle_{pos,neg}_tendon`` of length sum(section slides) - s sum(section hinges), the
chain's CC fibre length d_i - s Theta_i (``chain_params.muscle_tendon_coefs``), driven by a ``general``
actuator ``octarm_s{i}_muscle_{pos,neg}``: filterexact dynamics (tau = ``plant.muscle_time_constant``),
gain 1, no bias, ctrlrange [0, F_max] (``plant.muscle_max_force``): a force >= 0 lengthening its fibre.
Extensors: the OctArm's McKibben muscles lengthen under pressure, and sections in [L0, max_extension
L0] need a net extending force (pulling-only groups could hold only d <= L0).  Commands:
``chain_map.muscle_commands``.
Master: two motors.  Armature: ``armature_fraction`` times the section inertia scale on every chain
joint, plus one segment mass on the tip slide (see ``chain_params.joint_armature``), a modelled mismatch of
relative size ~ fraction / (6 N) in M2.

``enforce_cc``: joint equalities (hinges of a section equal; interior slides equal; first slide = half
the next; tip slide = half the last interior slide) and fixed-tendon equalities (boundary slide = mean
of its neighbours; for N = 1 one tendon s00 - s10 + s20 - tip = 0), solref/solimp ``CC_SOLREF``/
``CC_SOLIMP``: 3N - 3 hinge and 3N - 2 slide constraints leave exactly the 6 CC coordinates.

Stability (measured, default SlaveParams, 1 ms, implicitfast, loaded, correction every step): the
joint springs are integrated explicitly and the discrete chain gets stiffer with N (h w_max = 0.82,
1.19, 1.69, 2.39 at N = 8, 16, 32, 64; ``stiffness_courant_number``).  N <= 32 steps stably; N = 48
diverges in torque mode (use a smaller physics_dt, enforce_cc, or the ``discrete`` integrator, which
treats joint stiffness implicitly and was stable up to N = 64 at 1 ms).

The joint <-> q2 maps (sensing, actuation, elastic correction) and ``ChainMap`` live in
``harness.plant.chain_map``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import mujoco
import numpy as np

from controllers.params import MasterParams, SlaveParams
from harness.config.assets import asset_dir
from harness.config.scenario import ACTUATIONS, PlantConfig, Scenario
from harness.config.textio import atomic_path
from harness.plant.chain_map import ChainMap, _ro, chain_layout
from harness.plant.chain_params import (
    MUSCLE_SIDES,
    TIP_MASS_FRACTION,
    joint_armature,
    joint_damping,
    joint_stiffness,
    muscle_tendon_coefs,
    segment_inertias,
    servo_gains,
)
from harness.plant.environment import ContactMap, add_environment, clearance, contact_map
from harness.plant.initial import InitialStateError, initial_state

MJCF_DIR = asset_dir("mjcf")  # the shipped MJCF (package data when installed; harness.config.assets)
SCENE_XML = MJCF_DIR / "scene.xml"

N_SECTIONS = 3
MAX_SEGMENTS = 64
# Equality constraints holding the sections at constant curvature (api-notes: tight values).
CC_SOLREF = (0.002, 1.0)
CC_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)

_INTEGRATORS = {
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    "discrete": mujoco.mjtIntegrator.mjINT_DISCRETE,  # not in harness.config.INTEGRATORS (yet)
}


class PlantModelError(ValueError):
    """The plant model cannot be built: bad MJCF file (named, with MuJoCo's message) or bad option."""


# ================================================================================================
# Spec construction
# ================================================================================================

def _check_segments(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not (1 <= int(n) <= MAX_SEGMENTS):
        raise PlantModelError(f"plant.segments = {n!r}: must be an integer in [1, {MAX_SEGMENTS}]")
    return int(n)


def _load_spec(path: Path) -> mujoco.MjSpec:
    path = Path(path)
    if not path.is_file():
        raise PlantModelError(f"MJCF file not found: {path}")
    try:
        return mujoco.MjSpec.from_file(os.fspath(path))
    except ValueError as exc:  # MuJoCo's parse/resolve errors
        raise PlantModelError(f"cannot load MJCF {path}: {exc}") from None


def _compile(spec: mujoco.MjSpec, what: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        raise PlantModelError(f"cannot compile {what}: {exc}") from None


def _set_master(spec: mujoco.MjSpec, master: MasterParams, src: Path) -> None:
    """Overwrite lengths, inertials and joint damping of the master from MasterParams."""
    names = (("master_upper_link", "master_upper_link_geom", "master_shoulder_joint"),
             ("master_fore_link", "master_fore_link_geom", "master_elbow_joint"))
    for k, (body_name, geom_name, joint_name) in enumerate(names):
        body, geom, joint = spec.body(body_name), spec.geom(geom_name), spec.joint(joint_name)
        if body is None or geom is None or joint is None:
            raise PlantModelError(f"{src}: master element missing ({body_name}/{geom_name}/{joint_name})")
        l, mass = master.lengths[k], master.masses[k]
        i_rod = mass * l * l / 12.0
        body.mass = mass
        body.ipos = [0.0, 0.0, 0.5 * l]
        body.iquat = [1.0, 0.0, 0.0, 0.0]
        # about x = about y (slender rod); about z a thin-rod value, capped for the triangle inequality
        body.inertia = [i_rod, i_rod, min(1e-4 * mass, i_rod)]
        body.explicitinertial = True
        geom.fromto = [0.0, 0.0, 0.0, 0.0, 0.0, l]
        joint.damping[0] = master.damping[k]
        if k == 1:
            body.pos = [0.0, 0.0, master.lengths[0]]
    site = spec.site("master_tip_site")
    if site is None:
        raise PlantModelError(f"{src}: master_tip_site missing")
    site.pos = [0.0, 0.0, master.lengths[1]]


def _gravity(master: MasterParams, slave: SlaveParams) -> list[float]:
    gx, gz = slave.gravity
    if not np.allclose([gx, gz], [0.0, -master.gravity], rtol=1e-12, atol=1e-12):
        raise PlantModelError(
            f"master.gravity = {master.gravity} (along -Z) and slave.gravity = {slave.gravity} differ: "
            "both robots share one MuJoCo world")
    return [gx, 0.0, gz]


def _add_octarm(spec: mujoco.MjSpec, slave: SlaveParams, plant: PlantConfig, N: int, layout: dict, src: Path):
    base = spec.body("octarm_base")
    if base is None:
        raise PlantModelError(f"{src}: body octarm_base missing")
    d_hinge, d_slide = spec.find_default("octarm_hinge"), spec.find_default("octarm_slide")
    d_geom = spec.find_default("octarm_segment_visual")
    if d_hinge is None or d_slide is None or d_geom is None:
        raise PlantModelError(f"{src}: default classes octarm_hinge/octarm_slide/"
                              "octarm_segment_visual missing")
    L0 = np.asarray(slave.rest_lengths)
    l0 = L0 / N
    mass, iyy, tip_mass = segment_inertias(slave, N)
    stiff = joint_stiffness(slave, N, layout)
    arm = joint_armature(slave, N, layout, plant.armature_fraction)
    damp = joint_damping(slave, N, layout, plant.bending_viscosity, plant.extension_viscosity)
    joint_names = []
    parent = base
    c = 0
    for i in range(3):
        for j in range(N):
            if j >= 1:
                z = l0[i]
            elif i >= 1:
                z = 0.5 * (l0[i - 1] + l0[i])
            else:
                z = 0.5 * l0[0]
            name = f"octarm_s{i}_seg{j}"
            body = parent.add_body(name=f"{name}_body", pos=[0.0, 0.0, z])
            body.mass = float(mass[i, j])
            body.ipos = [0.0, 0.0, 0.0]
            # rod: about x = about y; about the rod axis a tiny but valid value
            body.inertia = [float(iyy[i, j]), float(iyy[i, j]), float(1e-3 * iyy[i, j])]
            body.explicitinertial = True
            for kind, dflt in (("slide", d_slide), ("hinge", d_hinge)):
                jn = body.add_joint(dflt, name=f"{name}_{kind}")
                jn.stiffness[0] = float(stiff[c])
                jn.damping[0] = float(damp[c])
                jn.armature = float(arm[c])
                joint_names.append(jn.name)
                c += 1
            body.add_geom(d_geom, name=f"{name}_geom",
                          fromto=[0.0, 0.0, -0.5 * l0[i], 0.0, 0.0, 0.5 * l0[i]])
            parent = body
    tip = parent.add_body(name="octarm_tip_body", pos=[0.0, 0.0, 0.5 * l0[2]])
    tip.mass = float(tip_mass)
    tip.ipos = [0.0, 0.0, 0.0]
    it = float(tip_mass * (0.1 * l0[2]) ** 2)
    tip.inertia = [it, it, it]
    tip.explicitinertial = True
    jn = tip.add_joint(d_slide, name="octarm_tip_slide")
    jn.stiffness[0] = float(stiff[c])
    jn.damping[0] = float(damp[c])
    jn.armature = float(arm[c])
    joint_names.append(jn.name)
    tip.add_site(name="octarm_tip_site")
    return joint_names, stiff, arm, tip_mass


def _add_muscles(spec: mujoco.MjSpec, joint_names: list[str], plant: PlantConfig, layout: dict,
                 N: int) -> list[str]:
    """Two one-sided muscle groups per section on fixed tendons (see the module docstring, Actuation)."""
    slide, hinge = muscle_tendon_coefs(N, layout)
    names = []
    for i in range(3):
        r = float(plant.muscle_radius[i])
        for side, tag in zip(MUSCLE_SIDES, ("pos", "neg"), strict=True):
            t = spec.add_tendon(name=f"octarm_s{i}_muscle_{tag}_tendon")
            for c, jn in enumerate(joint_names):
                cf = slide[i, c] - side * r * hinge[i, c]
                if cf != 0.0:
                    t.wrap_joint(jn, float(cf))
            a = spec.add_actuator(name=f"octarm_s{i}_muscle_{tag}", target=t.name,
                                  trntype=mujoco.mjtTrn.mjTRN_TENDON)
            a.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT
            a.dynprm[0] = float(plant.muscle_time_constant[i])
            a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            a.gainprm[0] = 1.0
            a.biastype = mujoco.mjtBias.mjBIAS_NONE
            a.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            a.ctrlrange = [0.0, float(plant.muscle_max_force[i])]
            names.append(a.name)
    return names


def _add_actuators(spec: mujoco.MjSpec, joint_names: list[str], actuation: str) -> list[str]:
    names = []
    for jn in joint_names:
        if actuation == "servo":
            a = spec.add_actuator(name=f"{jn}_servo", target=jn, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.set_to_position(kp=1.0, kv=0.0)  # gains set from the inertia in build_spec
        else:
            a = spec.add_actuator(name=f"{jn}_motor", target=jn, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.set_to_motor()
        names.append(a.name)
    return names


def _add_cc_equalities(spec: mujoco.MjSpec, N: int) -> None:
    """Equality constraints keeping each section at constant curvature (see module docstring)."""

    def joint_eq(name, j1, j2, a1):
        eq = spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_JOINT, name1=j1, name2=j2,
                               objtype=mujoco.mjtObj.mjOBJ_JOINT)
        eq.data[:5] = [0.0, a1, 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = list(CC_SOLREF), list(CC_SOLIMP)

    def tendon_eq(name, coefs):
        t = spec.add_tendon(name=f"{name}_tendon")
        for jn, cf in coefs:
            t.wrap_joint(jn, cf)
        eq = spec.add_equality(name=f"{name}_equality", type=mujoco.mjtEq.mjEQ_TENDON,
                               name1=t.name, objtype=mujoco.mjtObj.mjOBJ_TENDON)
        eq.data[:5] = [0.0, 0.0, 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = list(CC_SOLREF), list(CC_SOLIMP)

    def sl(i, j):
        return f"octarm_s{i}_seg{j}_slide"

    for i in range(3):
        for j in range(1, N):
            joint_eq(f"octarm_s{i}_seg{j}_hinge_equality", f"octarm_s{i}_seg{j}_hinge",
                     f"octarm_s{i}_seg0_hinge", 1.0)
    if N == 1:
        # 4 slides, 3 extensions: s00 - s10 + s20 - tip = 0 on the manifold
        tendon_eq("octarm_slide_cc", [(sl(0, 0), 1.0), (sl(1, 0), -1.0), (sl(2, 0), 1.0),
                                      ("octarm_tip_slide", -1.0)])
        return
    for i in range(3):
        for j in range(2, N):
            joint_eq(f"octarm_s{i}_seg{j}_slide_equality", sl(i, j), sl(i, 1), 1.0)
    joint_eq("octarm_s0_seg0_slide_equality", sl(0, 0), sl(0, 1), 0.5)
    for i in (1, 2):
        tendon_eq(f"octarm_s{i}_boundary", [(sl(i, 0), 1.0), (sl(i - 1, 1), -0.5), (sl(i, 1), -0.5)])
    joint_eq("octarm_tip_slide_equality", "octarm_tip_slide", sl(2, 1), 0.5)


def _validate_plant(plant: PlantConfig) -> int:
    N = _check_segments(plant.segments)
    if plant.actuation not in ACTUATIONS:
        raise PlantModelError(f"plant.actuation = {plant.actuation!r}: must be one of {ACTUATIONS}")
    if plant.integrator not in _INTEGRATORS:
        raise PlantModelError(
            f"plant.integrator = {plant.integrator!r}: must be one of {tuple(_INTEGRATORS)}")
    for f in ("physics_dt", "servo_frequency", "servo_damping_ratio"):
        v = getattr(plant, f)
        if not (np.isfinite(v) and v > 0):
            raise PlantModelError(f"plant.{f} = {v!r}: must be finite and > 0")
    for f in ("muscle_time_constant", "muscle_max_force", "muscle_radius"):
        if np.shape(v := getattr(plant, f)) != (3,) or not np.all(np.isfinite(v) & (np.asarray(v) > 0)):
            raise PlantModelError(f"plant.{f} = {v!r}: must be 3 finite numbers > 0")
    if not (np.isfinite(plant.armature_fraction) and plant.armature_fraction >= 0):
        raise PlantModelError(f"plant.armature_fraction = {plant.armature_fraction!r}: must be >= 0")
    return N


def _build(master: MasterParams, slave: SlaveParams, plant: PlantConfig, scene=None, environment=None):
    N = _validate_plant(plant)
    if scene is None:
        scene = getattr(plant, "scene_xml", None)
    scene = SCENE_XML if scene is None else Path(scene)
    spec = _load_spec(scene)
    spec.modelname = f"teleop_scene_n{N}"
    spec.option.timestep = float(plant.physics_dt)
    spec.option.integrator = _INTEGRATORS[plant.integrator]
    spec.option.gravity = _gravity(master, slave)
    _set_master(spec, master, scene)
    layout = chain_layout(N)
    joint_names, stiff, arm, tip_mass = _add_octarm(spec, slave, plant, N, layout, scene)
    muscle = plant.actuation == "muscle"
    act_names = (_add_muscles(spec, joint_names, plant, layout, N) if muscle
                 else _add_actuators(spec, joint_names, plant.actuation))
    if plant.enforce_cc:
        _add_cc_equalities(spec, N)
    if environment is not None and environment.objects:
        m0 = _compile(spec, "the plant model")
        invw = {m0.body(b).name: float(m0.body_invweight0[b, 0]) for b in range(m0.nbody)}
        arm_geoms = [(f"octarm_s{i}_seg{j}_geom", f"octarm_s{i}_seg{j}_body")
                     for i in range(3) for j in range(N)]
        add_environment(spec, environment, invw, arm_geoms)
    kp = np.zeros(len(joint_names))
    kv = np.zeros(len(joint_names))
    if plant.actuation == "servo":
        m = _compile(spec, "the plant model")
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)  # qpos0 = straight, rest length
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        dof = np.array([m.jnt_dofadr[m.joint(n).id] for n in joint_names])
        C = layout["C"]
        mass_u = np.einsum("ra,rs,sa->a", C, M[np.ix_(dof, dof)], C)  # diag(C^T M C)
        kp, kv = servo_gains(mass_u, N, layout, plant.servo_frequency, plant.servo_damping_ratio)
        for a_name, p, v in zip(act_names, kp, kv, strict=True):
            spec.actuator(a_name).set_to_position(kp=float(p), kv=float(v))
    return spec, N, layout, joint_names, act_names, stiff, arm, tip_mass, kp, kv


def build_spec(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
               scene_xml: str | os.PathLike | None = None) -> mujoco.MjSpec:
    """The plant as an editable ``mujoco.MjSpec`` (scene.xml + master from ``master`` + generated Octarm).

    master/slave: the *plant's* parameters (may differ from the controller's nominal ones).
    plant: segments N (int in [1, 64]), actuation, enforce_cc, physics_dt, integrator, servo tuning,
    armature_fraction.  scene_xml: alternative scene file (default ``mjcf/scene.xml``); it must define
    the named master elements, ``octarm_base`` and the ``octarm_*`` default classes.
    Raises PlantModelError on bad input or MJCF.
    """
    return _build(master, slave, plant, scene_xml)[0]


def build_model(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
                scene_xml: str | os.PathLike | None = None,
                environment=None) -> tuple[mujoco.MjModel, ChainMap]:
    """Compiled plant model and its ``ChainMap`` (addresses + constant maps); see ``build_spec``.
    environment: an `EnvironmentConfig` whose objects are added (`harness.plant.environment`)."""
    spec, N, layout, joint_names, act_names, stiff, arm, tip_mass, kp, kv = _build(master, slave, plant,
                                                                                   scene_xml, environment)
    m = _compile(spec, "the plant model")
    act_ids = [m.actuator(n).id for n in act_names]
    muscle = plant.actuation == "muscle"
    Ke = np.asarray(slave.extension_stiffness)
    shape_w = np.where(layout["is_hinge"] == 0, stiff, 0.0)

    def jid(name):
        return m.joint(name).id

    master_j = [jid("master_shoulder_joint"), jid("master_elbow_joint")]
    chain_j = [jid(n) for n in joint_names]
    cmap = ChainMap(
        n_segments=N,
        actuation=plant.actuation,
        enforce_cc=bool(plant.enforce_cc),
        master_qpos_adr=_ro(m.jnt_qposadr[master_j], np.int64),
        master_dof_adr=_ro(m.jnt_dofadr[master_j], np.int64),
        master_actuator_ids=_ro([m.actuator(n).id for n in ("master_shoulder_motor", "master_elbow_motor")],
                                np.int64),
        chain_qpos_adr=_ro(m.jnt_qposadr[chain_j], np.int64),
        chain_dof_adr=_ro(m.jnt_dofadr[chain_j], np.int64),
        chain_actuator_ids=_ro([] if muscle else act_ids, np.int64),
        muscle_actuator_ids=_ro(act_ids if muscle else [], np.int64),
        muscle_radius=_ro(plant.muscle_radius),
        muscle_max_force=_ro(plant.muscle_max_force),
        master_site_id=int(m.site("master_tip_site").id),
        tip_site_id=int(m.site("octarm_tip_site").id),
        master_base_pos=_ro(m.body("master_base").pos),
        octarm_base_pos=_ro(m.body("octarm_base").pos),
        C=_ro(layout["C"]),
        R=_ro(layout["R"]),
        L0=_ro(slave.rest_lengths),
        section=_ro(layout["section"], np.int64),
        is_hinge=_ro(layout["is_hinge"], np.int64),
        segment=_ro(layout["segment"], np.int64),
        joint_stiffness=_ro(stiff),
        shape_stiffness=_ro(shape_w),
        seg_kb=_ro(N * np.asarray(slave.bending_stiffness)),
        ke=_ro(Ke),
        armature=_ro(arm),
        servo_kp=_ro(kp),
        servo_kv=_ro(kv),
        tip_mass=float(tip_mass),
    )
    return m, cmap


@dataclass(frozen=True, eq=False)
class MujocoPlant:
    """A built MuJoCo plant: the compiled model (plant parameters, segments, actuation) and its ChainMap.
    `harness.loop.simulate` takes it; one plant can serve several runs of the same scenario plant."""

    model: mujoco.MjModel
    cmap: ChainMap
    contact: ContactMap | None = None  # contact sensors and objects (None = no environment)
    kind: ClassVar[str] = "mujoco"

    @classmethod
    def build(cls, scn: Scenario) -> MujocoPlant:
        """Build from the scenario's plant side (raises PlantModelError on bad MJCF or options, and
        when an environment object intersects the arm at the initial state)."""
        m, cmap = build_model(scn.plant_master, scn.plant_slave, scn.plant, environment=scn.environment)
        if not scn.environment.objects:
            return cls(m, cmap)
        cm = contact_map(m)
        _check_clearance(m, cmap, cm, scn)
        return cls(m, cmap, cm)


def _check_clearance(m: mujoco.MjModel, cmap: ChainMap, cm: ContactMap, scn: Scenario) -> None:
    """PlantModelError naming the object if it intersects the arm at the scenario's initial state."""
    try:
        s0 = initial_state(scn)
    except InitialStateError:
        return  # reported by the loop as an impossible start
    d = mujoco.MjData(m)
    d.qpos[cmap.master_qpos_adr] = s0[0:2]
    cmap.set_q2(d, s0[4:10], s0[10:16])
    mujoco.mj_forward(m, d)
    hits = clearance(m, d, cm)
    if hits:
        g_obj, g_arm, dist = min(hits, key=lambda h: h[2])
        name = m.geom(g_obj).name[len("env_"):-len("_geom")]
        raise PlantModelError(
            f"environment.objects.{name}: intersects the slave at t = 0 ({m.geom(g_arm).name} penetrates "
            f"{-dist:.4g} m); move the object or the initial state")


def stiffness_courant_number(m: mujoco.MjModel, cm: ChainMap) -> float:
    """h * w_max of the chain's joint springs (and servo kp) against its inertia at qpos0 (dimensionless).

    w_max^2 is the largest generalized eigenvalue of K = diag(joint stiffness + kp) and the chain block of
    M (armature included).  Semi-implicit integration of undamped springs needs h w_max < 2; servo
    damping (implicit under implicitfast) and equality constraints relax this in practice.
    """
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    idx = np.asarray(cm.chain_dof_adr)
    Mc = M[np.ix_(idx, idx)]
    k = np.asarray(cm.joint_stiffness) + np.asarray(cm.servo_kp)
    # eigenvalues of L^-1 K L^-T with M = L L^T
    L = np.linalg.cholesky(Mc)
    Li = np.linalg.inv(L)
    w2 = np.linalg.eigvalsh(Li @ (k[:, None] * Li.T))
    return float(m.opt.timestep * np.sqrt(max(w2[-1], 0.0)))


def export_mjcf(master: MasterParams, slave: SlaveParams, plant: PlantConfig, path) -> Path:
    """Write the generated plant MJCF (``spec.to_xml()``) to ``path`` and check it re-loads.

    The file is self-contained (includes resolved) and opens in MuJoCo's viewer for any N.  MuJoCo
    writes numbers with about 6 significant digits, so simulate with ``build_model`` (full precision);
    the export is for viewing and sharing.
    """
    spec = build_spec(master, slave, plant)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    xml = spec.to_xml()
    with atomic_path(path) as tmp:  # renamed into place only once written and re-loaded
        tmp.write_text(xml, encoding="utf-8")
        try:
            mujoco.MjModel.from_xml_string(xml)
        except ValueError as exc:
            raise PlantModelError(f"exported MJCF {path} does not re-load: {exc}") from None
    return path


__all__ = [
    "CC_SOLIMP", "CC_SOLREF", "MJCF_DIR", "SCENE_XML", "TIP_MASS_FRACTION", "ChainMap", "MujocoPlant",
    "PlantModelError",
    "build_model", "build_spec", "export_mjcf", "stiffness_courant_number",
]
