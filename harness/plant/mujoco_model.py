"""MuJoCo plant: the master and a discretized Octarm built by editing an MjSpec of ``mjcf/`` (model and
actuations: docs/plants.md; maps: `chain_map`; per-joint parameters: `chain_params`).  SI units; both
robots move in planes parallel to world x-z, hinges turn about +y; task space [X, Z] relative to each base.

Section i (d_i, k_i, Theta_i = k_i d_i, rest L0_i) is N segments: body ``octarm_s{i}_seg{j}_body`` at the
segment midpoint has a slide ``..._slide`` along the parent's tangent, then a hinge ``..._hinge``;
``octarm_tip_body`` (``octarm_tip_slide``, ``octarm_tip_site``) ends the chain.  On the CC manifold, with
e_i = d_i - L0_i: hinge(i, j) = Theta_i / N, slide(i, j >= 1) = e_i / N, slide(i, 0) = (e_{i-1} + e_i)
/ (2N) (e_{-1} = 0), tip slide = e_2 / (2N), i.e. joints = C [e, Theta] (n_chain = 6N + 1, MuJoCo order).
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
from harness.config.scenario import INTEGRATORS, PlantConfig, Scenario
from harness.config.textio import atomic_path
from harness.plant.chain_map import ChainMap, chain_layout
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

# equality constraints holding the sections at constant curvature (api-notes: tight values)
CC_SOLREF = (0.002, 1.0)
CC_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)

# the scenario's integrators, and "discrete" (not in harness.config.INTEGRATORS)
_INTEGRATORS = {n: getattr(mujoco.mjtIntegrator, f"mjINT_{n.upper()}") for n in (*INTEGRATORS, "discrete")}


class PlantModelError(ValueError):
    """The plant model cannot be built: bad MJCF file (named, with MuJoCo's message) or bad option;
    `path`: the scenario field at fault, when known."""

    def __init__(self, message: str, path: str | None = None) -> None:
        super().__init__(message)
        self.path = path


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
    gm, (gx, gz) = float(master.gravity), slave.gravity
    if not np.allclose([gx, gz], [0.0, -gm], rtol=1e-12, atol=1e-12):
        raise PlantModelError(
            f"plant.master.gravity = {gm:g} and plant.slave.gravity = [{gx:g}, {gz:g}] differ: the MuJoCo "
            f"plant has one world for both robots, so plant.slave.gravity must be [0, {-gm:g}] (set both, or "
            "neither)", "plant.slave.gravity")
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

    def add_joint(body, dflt, name):
        c = len(joint_names)
        jn = body.add_joint(dflt, name=name)
        jn.stiffness[0] = float(stiff[c])
        jn.damping[0] = float(damp[c])
        jn.armature = float(arm[c])
        joint_names.append(name)

    parent = base
    for i in range(3):
        for j in range(N):
            if j >= 1:
                z = l0[i]
            elif i >= 1:
                z = 0.5 * (l0[i - 1] + l0[i])
            else:
                z = 0.5 * l0[0]
            name = f"octarm_s{i}_seg{j}"
            # rod: about x = about y; about the rod axis a tiny but valid value
            body = parent.add_body(name=f"{name}_body", pos=[0.0, 0.0, z], mass=float(mass[i, j]),
                                   ipos=[0.0, 0.0, 0.0], explicitinertial=True,
                                   inertia=[float(iyy[i, j]), float(iyy[i, j]), float(1e-3 * iyy[i, j])])
            add_joint(body, d_slide, f"{name}_slide")
            add_joint(body, d_hinge, f"{name}_hinge")
            body.add_geom(d_geom, name=f"{name}_geom",
                          fromto=[0.0, 0.0, -0.5 * l0[i], 0.0, 0.0, 0.5 * l0[i]])
            parent = body
    it = float(tip_mass * (0.1 * l0[2]) ** 2)
    tip = parent.add_body(name="octarm_tip_body", pos=[0.0, 0.0, 0.5 * l0[2]], mass=float(tip_mass),
                          ipos=[0.0, 0.0, 0.0], inertia=[it, it, it], explicitinertial=True)
    add_joint(tip, d_slide, "octarm_tip_slide")
    tip.add_site(name="octarm_tip_site")
    return joint_names, stiff


def _add_muscles(spec: mujoco.MjSpec, joint_names: list[str], plant: PlantConfig, layout: dict,
                 N: int) -> list[str]:
    """Two one-sided extensor groups per section on fixed tendons (docs/plants.md)."""
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
                                  trntype=mujoco.mjtTrn.mjTRN_TENDON, dyntype=mujoco.mjtDyn.mjDYN_FILTEREXACT,
                                  gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_NONE,
                                  ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
                                  ctrlrange=[0.0, float(plant.muscle_max_force[i])])
            a.dynprm[0] = float(plant.muscle_time_constant[i])
            a.gainprm[0] = 1.0
            names.append(a.name)
    return names


def _add_actuators(spec: mujoco.MjSpec, joint_names: list[str], actuation: str) -> list[str]:
    """A servo (made a position actuator with its gains in `_build`) or a motor per chain joint."""
    kind = "servo" if actuation == "servo" else "motor"
    for jn in joint_names:
        spec.add_actuator(name=f"{jn}_{kind}", target=jn, trntype=mujoco.mjtTrn.mjTRN_JOINT).set_to_motor()
    return [f"{jn}_{kind}" for jn in joint_names]


def _add_cc_equalities(spec: mujoco.MjSpec, N: int) -> None:
    """Joint equalities (name, joint, joint it follows, ratio) and tendon equalities (name, [(joint,
    coefficient)], sum = 0) holding each section at constant curvature."""

    def sl(i, j):
        return f"octarm_s{i}_seg{j}_slide"

    eqs = [(f"octarm_s{i}_seg{j}_hinge_equality", f"octarm_s{i}_seg{j}_hinge", f"octarm_s{i}_seg0_hinge", 1.0)
           for i in range(3) for j in range(1, N)]
    if N == 1:  # 4 slides, 3 extensions: s00 - s10 + s20 - tip = 0 on the manifold
        eqs.append(("octarm_slide_cc", [(sl(0, 0), 1.0), (sl(1, 0), -1.0), (sl(2, 0), 1.0),
                                        ("octarm_tip_slide", -1.0)]))
    else:
        eqs += [(f"{sl(i, j)}_equality", sl(i, j), sl(i, 1), 1.0) for i in range(3) for j in range(2, N)]
        eqs.append((f"{sl(0, 0)}_equality", sl(0, 0), sl(0, 1), 0.5))
        eqs += [(f"octarm_s{i}_boundary", [(sl(i, 0), 1.0), (sl(i - 1, 1), -0.5), (sl(i, 1), -0.5)])
                for i in (1, 2)]
        eqs.append(("octarm_tip_slide_equality", "octarm_tip_slide", sl(2, 1), 0.5))
    for name, *rest in eqs:
        if len(rest) == 1:  # a tendon
            t = spec.add_tendon(name=f"{name}_tendon")
            for jn, cf in rest[0]:
                t.wrap_joint(jn, cf)
            eq = spec.add_equality(name=f"{name}_equality", type=mujoco.mjtEq.mjEQ_TENDON, name1=t.name,
                                   objtype=mujoco.mjtObj.mjOBJ_TENDON)
            eq.data[:5] = [0.0, 0.0, 0.0, 0.0, 0.0]
        else:
            eq = spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_JOINT, name1=rest[0], name2=rest[1],
                                   objtype=mujoco.mjtObj.mjOBJ_JOINT)
            eq.data[:5] = [0.0, rest[2], 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = list(CC_SOLREF), list(CC_SOLIMP)


def _build(master: MasterParams, slave: SlaveParams, plant: PlantConfig, scene=None, environment=None):
    N = int(plant.segments)  # plant options: validated by the scenario schema
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
    joint_names, stiff = _add_octarm(spec, slave, plant, N, layout, scene)
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
    kp = kv = np.zeros(len(joint_names))
    if plant.actuation == "servo":
        m = _compile(spec, "the plant model")
        dof = np.array([m.jnt_dofadr[m.joint(n).id] for n in joint_names])
        C = layout["C"]
        mass_u = np.einsum("ra,rs,sa->a", C, _mass_matrix0(m)[np.ix_(dof, dof)], C)  # diag(C^T M C)
        kp, kv = servo_gains(mass_u, N, layout, plant.servo_frequency, plant.servo_damping_ratio)
        for a_name, p, v in zip(act_names, kp, kv, strict=True):
            spec.actuator(a_name).set_to_position(kp=float(p), kv=float(v))
    return spec, N, layout, joint_names, act_names, stiff, kp, kv


def _mass_matrix0(m: mujoco.MjModel) -> np.ndarray:
    """The joint-space inertia (nv, nv) at qpos0 (straight, rest length), armature included."""
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return M


def build_spec(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
               scene_xml: str | os.PathLike | None = None) -> mujoco.MjSpec:
    """The plant as an editable ``mujoco.MjSpec``: scene.xml (or scene_xml, defining the master elements,
    ``octarm_base`` and the ``octarm_*`` default classes) with the master and the generated Octarm from the
    plant's own parameters.  Raises PlantModelError on bad input or MJCF."""
    return _build(master, slave, plant, scene_xml)[0]


def build_model(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
                scene_xml: str | os.PathLike | None = None,
                environment=None) -> tuple[mujoco.MjModel, ChainMap]:
    """Compiled plant model and its ``ChainMap`` (see ``build_spec``); environment: an
    `EnvironmentConfig` whose objects are added (`harness.plant.environment`)."""
    spec, N, layout, joint_names, act_names, stiff, kp, kv = _build(master, slave, plant, scene_xml,
                                                                    environment)
    m = _compile(spec, "the plant model")
    act_ids = [m.actuator(n).id for n in act_names]
    muscle = plant.actuation == "muscle"
    master_j = [m.joint("master_shoulder_joint").id, m.joint("master_elbow_joint").id]
    chain_j = [m.joint(n).id for n in joint_names]
    cmap = ChainMap(
        n_segments=N, actuation=plant.actuation, enforce_cc=bool(plant.enforce_cc),
        master_qpos_adr=m.jnt_qposadr[master_j], master_dof_adr=m.jnt_dofadr[master_j],
        master_actuator_ids=[m.actuator(n).id for n in ("master_shoulder_motor", "master_elbow_motor")],
        chain_qpos_adr=m.jnt_qposadr[chain_j], chain_dof_adr=m.jnt_dofadr[chain_j],
        chain_actuator_ids=[] if muscle else act_ids, muscle_actuator_ids=act_ids if muscle else [],
        muscle_radius=plant.muscle_radius, muscle_max_force=plant.muscle_max_force,
        master_site_id=int(m.site("master_tip_site").id), tip_site_id=int(m.site("octarm_tip_site").id),
        master_base_pos=m.body("master_base").pos, octarm_base_pos=m.body("octarm_base").pos,
        C=layout["C"], R=layout["R"], L0=slave.rest_lengths, section=layout["section"],
        is_hinge=layout["is_hinge"], segment=layout["segment"], joint_stiffness=stiff,
        shape_stiffness=np.where(layout["is_hinge"] == 0, stiff, 0.0),
        seg_kb=N * np.asarray(slave.bending_stiffness), ke=slave.extension_stiffness, servo_kp=kp,
        servo_kv=kv)
    return m, cmap


@dataclass(frozen=True, eq=False)
class MujocoPlant:
    """A built MuJoCo plant: the compiled model and its ChainMap (one plant serves several runs)."""

    model: mujoco.MjModel
    cmap: ChainMap
    contact: ContactMap | None = None  # contact sensors and objects (None = no environment)
    kind: ClassVar[str] = "mujoco"

    @classmethod
    def build(cls, scn: Scenario) -> MujocoPlant:
        """Build from the scenario's plant side.  Raises PlantModelError on bad MJCF or options, or when
        an environment object intersects the arm at the initial state."""
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
            f"{-dist:.4g} m); move the object or the initial state", f"environment.objects.{name}")


def export_mjcf(master: MasterParams, slave: SlaveParams, plant: PlantConfig, path) -> Path:
    """Write the generated plant MJCF (``spec.to_xml()``, self-contained, ~6 significant digits: for viewing;
    simulate with ``build_model``) to ``path``, atomically, once it re-loads."""
    spec = build_spec(master, slave, plant)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    xml = spec.to_xml()
    with atomic_path(path) as tmp:
        tmp.write_text(xml, encoding="utf-8")
        try:
            mujoco.MjModel.from_xml_string(xml)
        except ValueError as exc:
            raise PlantModelError(f"exported MJCF {path} does not re-load: {exc}") from None
    return path


__all__ = ["CC_SOLIMP", "CC_SOLREF", "MJCF_DIR", "SCENE_XML", "TIP_MASS_FRACTION", "ChainMap", "MujocoPlant",
           "PlantModelError", "build_model", "build_spec", "export_mjcf"]
