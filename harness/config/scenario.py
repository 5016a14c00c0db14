"""The scenario schema, declared once: each field's type, default, range and description.  The
`controllers.params` dataclasses keep their names and defaults; their ranges and descriptions are
`MASTER`, `SLAVE`, `GAINS`, `SUBTASK` here.  Defaults reproduce the paper scenario (Sec. VI)."""

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

from controllers.params import SUBTASKS, Gains, MasterParams, SlaveParams, SubtaskSpec
from harness.config.errors import short_repr
from harness.config.schema import Meta, checked, doc, integer, num, vec

PLANTS = ("mujoco", "analytic", "cosserat")
ELASTIC_LAWS = ("analytic", "linear")
ACTUATIONS = ("servo", "torque", "muscle")
INTEGRATORS = ("implicitfast", "implicit", "euler", "rk4")
ENV_KINDS = ("plane", "box", "sphere")
FORCE_MODES = ("exact", "sensed", "ignored")
NOISE_MODELS = ("per_channel", "per_vector")
NAME_RE = r"^[A-Za-z0-9_][A-Za-z0-9_.+=,@-]{0,99}$"
NAME_EXPECT = ("a string of 1-100 letters, digits or _ . + = , @ - (usable as a folder name; no spaces or "
               "slashes, not starting with '.' or '-')")
KEY_RE = r"^[A-Za-z_][A-Za-z0-9_-]*$"
CONTROLLER_RE = r"^(?:[A-Za-z_][A-Za-z0-9_]*|[^\x00-\x1f:][^\x00-\x1f]*:[A-Za-z_][A-Za-z0-9_]*)$"
CONTROLLER_EXPECT = ("a built-in controller name (see 'teleop controllers'), 'path/to/file.py:ClassName' or "
                     "'package.module:ClassName'")
TARGETS_EXPECT = "an array of [t, X, Z] triples (s, m, m) with strictly increasing t >= 0"
POS, NONNEG = {"gt": 0.0}, {"ge": 0.0}

# ranges and descriptions of the controller side's parameter dataclasses (names/defaults: theirs)
MASTER = {
    "lengths": vec(2, "m, link lengths l1, l2 (paper Sec. VI)", **POS),
    "masses": vec(2, "kg, link masses (uniform rods; our proposal)", **POS),
    "damping": vec(2, "N m s/rad, viscous joint friction", **NONNEG),
    "gravity": num("m/s^2, gravity along -Z", **NONNEG),
}
SLAVE = {
    "rest_lengths": vec(3, "L0, m, section rest lengths, base to tip", **POS),
    "masses": vec(3, "kg, section masses, base to tip", **POS),
    "bending_stiffness": vec(3, "Kb, N m^2, bending stiffness per section", **NONNEG),
    "extension_stiffness": vec(3, "Ke, N/m, extension stiffness per section", **NONNEG),
    "extension_damping": vec(3, "N s/m, viscous damping of the section-length rates", **NONNEG),
    "bending_damping": vec(3, "N m^2 s, viscous damping of the curvature rates", **NONNEG),
    "slice_inertia": vec(3, "kg m^2 per unit material length, rotary inertia of the cross-sections",
                         **NONNEG),
    "gravity": vec(2, "m/s^2, gravity vector (X, Z)"),
    "max_extension": num("section length range [L0, max_extension * L0]", gt=1.0, le=100.0),
    "max_bend": num("rad, |k_i d_i| <= max_bend", gt=0.0, le=math.pi),
    "n_quad": integer("Gauss-Legendre points per section for the energy integrals", ge=2, le=32),
}
GAINS = {k: num(f"gain {k} of the paper's law, eq. (39)", **POS) for k in "k1 k2 k3 k4 ky ks kn".split()}
SUBTASK = {
    "kinds": doc(tuple[Literal[SUBTASKS], ...], "null-space sub-tasks (29)-(33): 'manipulability' (41), "
                 "'limits'; distinct"),
    "weights": doc(tuple[Annotated[float, Meta(gt=0.0)], ...], "one weight per kind, each > 0 (default: 1.0 "
                   "manipulability, 0.05 limits)"),
    "limit_power": integer("shape of the limits term", ge=1, le=10),
}
Master, Slave, GainsSpec, Subtask = (checked(c, s) for c, s in ((MasterParams, MASTER), (SlaveParams, SLAVE),
                                                                 (Gains, GAINS), (SubtaskSpec, SUBTASK)))


@dataclass(frozen=True)
class TrajectoryConfig:
    center: vec(2, "m; x_d(t) must stay inside the master workspace annulus [|l1 - l2| + 1 mm, "
                "l1 + l2 - 1 mm] (nominal and plant master)") = (0.0, 1.0)
    amplitude: vec(2, "m") = (0.01, 0.01)
    omega: num("rad/s; |omega| < pi / control_dt") = 1.0


@dataclass(frozen=True)
class InitialState:
    master_offset: vec(2, "m, added to x_d(0) before the master inverse kinematics") = (0.0, 0.0)
    master_elbow: doc(Literal[-1, 1], "sign of the elbow angle q_b of the IK solution") = -1
    slave_q2: doc(vec(6, "") | None, '[d1, d2, d3, k1, k2, k3] (m, 1/m); "none" = equal sections under '
                  "the master tip") = None
    slave_curvature: num('1/m, section curvature "near 0" used when slave_q2 = "none"') = 1e-3


@dataclass(frozen=True)
class CosseratConfig:
    elements_per_section: integer("rod elements per section", ge=2, le=200) = 10
    dt: doc(num("", gt=0.0, le=0.01) | Literal["auto"], 's, rod time step, or "auto" (largest control_dt / m '
            "below the stable step)") = "auto"
    shear_factor: num("shear stiffness GA as a multiple of EA (docs/rod-convergence.md)", gt=0.0,
                       le=1e6) = 100.0
    rotary_radius: num("m, disc radius of the rotary inertia when slave.slice_inertia = 0", gt=0.0,
                       le=1.0) = 0.04
    elastic_law: doc(Literal[ELASTIC_LAWS], '"analytic" (energy of the CC model) | "linear" '
                     "(textbook rod)") = "analytic"


@dataclass(frozen=True)
class PlantConfig:
    kind: doc(Literal[PLANTS], '"mujoco" | "analytic" (RK4 on the analytic model) | "cosserat" (rod)') = \
        "mujoco"
    master: doc(Master | None, '"none" = same as [master]; or a [plant.master] table whose missing keys '
                "take the nominal [master] value") = None
    slave: doc(Slave | None, '"none" = same as [slave]; or a [plant.slave] table whose missing keys take '
               "the nominal [slave] value") = None
    actuation: doc(Literal[ACTUATIONS], '"servo" (position servos tracking the integrated command; hide the '
                   'slave\'s inertia) | "torque" (T2 as ideal generalized forces) | "muscle" (two one-sided '
                   "groups per section with force dynamics and limits); see docs/plants.md") = "servo"
    segments: integer("rigid segments per section N (mujoco only)", ge=1, le=64) = 8
    enforce_cc: doc(bool, "equality constraints holding each section at constant curvature (mujoco "
                    "only)") = False
    physics_dt: num("s, MuJoCo timestep / RK4 step", gt=0.0, le=0.01) = 0.001
    integrator: doc(Literal[INTEGRATORS], "MuJoCo integrator") = "implicitfast"
    servo_frequency: num("Hz, servo natural frequency of each section's CC coordinate (its N segment "
                         "servos in series, gains per unit length)", gt=0.0, le=1000.0) = 20.0
    servo_damping_ratio: num("servo damping ratio (section level)", **POS) = 1.0
    servo_feedforward: doc(bool, "add the analytic T2 (mapped to segment joints) in servo mode") = True
    actuation_delay: num("s, pure command delay, a multiple of control_dt", **NONNEG) = 0.0
    muscle_time_constant: vec(3, "s, tau of the muscle groups' first-order force dynamics per section",
                              gt=0.0, le=10.0) = (0.05, 0.05, 0.05)
    muscle_max_force: vec(3, "N, force limit F_max of one muscle group per section", gt=0.0,
                          le=1e5) = (400.0, 300.0, 200.0)
    muscle_radius: vec(3, "m, lateral offset of the two groups from the backbone per section (default: "
                       "sqrt(Kb / (Ke L0)) of the default [slave], rounded)", gt=0.0,
                       le=0.5) = (0.16, 0.12, 0.09)
    armature_fraction: num("segment-joint armature as a fraction of the section inertia", **NONNEG) = 0.01
    scene_xml: doc(doc(str, "", expect="the path of an existing MJCF scene file") | None,
                   "alternative scene MJCF file (must include master + octarm base); relative paths "
                   'from the current directory; "none" = the shipped scene') = None
    bending_viscosity: vec(3, "eta_b, N m^2 s, material (Kelvin-Voigt) bending viscosity per section; "
                           "MuJoCo chain: hinge damping eta_b / h", **NONNEG) = (0.1, 0.1, 0.1)
    extension_viscosity: vec(3, "eta_a, N s, material extension viscosity per section; MuJoCo chain: "
                             "slide damping eta_a / h", **NONNEG) = (3.0, 3.0, 3.0)
    cosserat: doc(CosseratConfig, "Cosserat-rod plant numerics (kind = \"cosserat\"; material: [plant.slave] "
                  "and the viscosities of [plant])") = \
        field(default_factory=CosseratConfig)


@dataclass(frozen=True)
class FaultConfig:
    e2_sign: doc(Literal[-1, 1], "-1 flips the sign of the coordination-error feedback in (18)") = 1
    null_space_scale: num("multiplies phi_N (27): 0 = null-space term dropped, 1 = intact", ge=0.0,
                          le=10.0) = 1.0


_LEAF = bool | int | float | str
ParamValue = doc(_LEAF | list[_LEAF | list[_LEAF | list[_LEAF]]], "",
                 expect="a boolean, number, string or array of these")


@dataclass(frozen=True)
class ControllerConfig:
    name: doc(str, '"paper" (the paper\'s law, compiled), another built-in ("teleop controllers") or '
              '"path/to/file.py:ClassName" / "package.module:ClassName"', pattern=CONTROLLER_RE,
              expect=CONTROLLER_EXPECT) = "paper"
    params: doc(dict[doc(str, "", pattern=KEY_RE), ParamValue],
                "the controller's own parameters (booleans, numbers, strings, arrays)") = \
        field(default_factory=dict)
    step_timeout: doc(num("", gt=0.0, le=86400.0) | None,
                      's, the longest a Python controller\'s call may run ("none": no limit); construction, '
                      "reset and the first step may take at least 120 s (they may compile the nominal "
                      "models)") = 10.0


@dataclass(frozen=True)
class EnvObject:
    """An object the slave can touch ([X, Z] m, Octarm base frame); frictionless linear contact."""

    name: doc(str, "object name (the key of its [environment.objects.<name>] table)", pattern=NAME_RE,
              expect=NAME_EXPECT) = "wall"
    kind: doc(Literal[ENV_KINDS], '"plane" | "box" | "sphere"') = "plane"
    position: vec(2, "m, slave task frame [X, Z]") = (0.0, 1.2)
    normal: vec(2, "plane only: direction toward the free side (normalised), non-zero") = (0.0, -1.0)
    size: vec(2, "m, box half sizes [X, Z]; sphere radius = size[0]", **POS) = (0.05, 0.05)
    angle: num("rad, box rotation about +y") = 0.0
    stiffness: num("N/m, normal contact stiffness", **POS) = 1.0e4
    damping_ratio: num("critical-damping fraction against the touching body's mass", **NONNEG) = 1.0

    def __post_init__(self) -> None:
        if self.kind == "plane" and math.hypot(*self.normal) < 1e-9:
            raise ValueError(f"normal = {list(self.normal)}: must be a non-zero vector")


@dataclass(frozen=True)
class EnvironmentConfig:
    objects: doc(tuple[EnvObject, ...], "one [environment.objects.<name>] table per object (see "
                 "scenarios/contact.toml)", item="<name>") = ()

    def __post_init__(self) -> None:
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ValueError(f"objects = {names}: object names must be distinct")


@dataclass(frozen=True)
class ForceSensingConfig:
    mode: doc(Literal[FORCE_MODES], '"exact" (true forces) | "sensed" (noise, filter, delay) | "ignored" '
              "(F = 0)") = "exact"
    noise_std: num("N, white noise per component (sensed mode)", **NONNEG) = 0.0
    cutoff: doc(num("", **POS) | None, 'Hz, first-order low-pass cutoff (sensed mode); "none" = '
                "unfiltered") = None
    delay: num("s, a multiple of control_dt (sensed mode)", **NONNEG) = 0.0


@dataclass(frozen=True)
class SensingConfig:
    force: doc(ForceSensingConfig, "what the laws (13), (17) get as F = [F1, F2]") = \
        field(default_factory=ForceSensingConfig)
    dq2_cutoff: doc(num("", **POS) | None, 'Hz, first-order low-pass on the sensed dq2 (after the noise; '
                    'the laws get the filtered rates); "none" = unfiltered') = None


@dataclass(frozen=True)
class OperatorConfig:
    enabled: doc(bool, "simulate the operator's hand") = False
    mass: num("kg, hand mass", **POS) = 0.5
    stiffness: num("N/m, arm spring toward the target", **NONNEG) = 200.0
    damping: num("N s/m, arm damper (absolute hand velocity)", **NONNEG) = 20.0
    grip_stiffness: num("N/m, hand-handle spring", **POS) = 2000.0
    grip_damping: num("N s/m, hand-handle damper", **NONNEG) = 40.0
    targets: doc(tuple[vec(3, ""), ...], "[[t, X, Z], ...] (s, m, master task frame), piecewise linear, "
                 "t >= 0 strictly increasing; [] = hold the initial tip position",
                 expect=TARGETS_EXPECT) = ()

    def __post_init__(self) -> None:
        ts = [r[0] for r in self.targets]
        if any(t < 0 for t in ts) or any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
            targets = short_repr([list(r) for r in self.targets])
            raise ValueError(f"targets = {targets}: must be {TARGETS_EXPECT}")


@dataclass(frozen=True)
class Scenario:
    """One fully resolved run."""

    name: doc(str, "run name; default output folder runs/<name> (default: the file's stem)",
              pattern=NAME_RE, expect=NAME_EXPECT) = "paper"
    duration: num("s, simulated time", gt=0.0, le=3600.0) = 20.0
    control_dt: num("s, control period; an integer multiple of plant.physics_dt", gt=0.0, le=1.0) = 0.001
    snr_db: doc(num("", ge=0.0, le=200.0) | None, 'dB, AWGN on the fed-back states; "none" = no '
                "noise") = 40.0
    noise_model: doc(Literal[NOISE_MODELS], '"per_channel": SNR per signal (running power); "per_vector": '
                     "per-step RMS of each fed-back vector") = "per_channel"
    seed: integer("noise seed", ge=0, le=2**63 - 1) = 0
    transient: num("s, RMS/max metrics are taken after this time, < duration (default: 5, or a quarter "
                   "of a shorter duration)", ge=0.0, lt=3600.0) = 5.0
    gains: doc(GainsSpec, "controller gains, paper eq. (39)") = field(default_factory=Gains)
    master: doc(Master, "NOMINAL master model used by the controller (2-link planar arm)") = \
        field(default_factory=MasterParams)
    slave: doc(Slave, "NOMINAL Octarm model used by the controller (3 constant-curvature sections; our "
               "proposal)") = field(default_factory=SlaveParams)
    subtask: doc(Subtask, "null-space sub-tasks (29)-(33)") = field(default_factory=SubtaskSpec)
    trajectory: doc(TrajectoryConfig, "x_d(t) = [cx + ax sin(w t), cz + az cos(w t)] (m, master base "
                    "frame), paper eq. (40)") = field(default_factory=TrajectoryConfig)
    initial: doc(InitialState, "initial state, both arms at rest") = field(default_factory=InitialState)
    plant: doc(PlantConfig, 'the "true" plant the controller drives (its own master / slave models)') = \
        field(default_factory=PlantConfig)
    interaction_forces: doc(tuple[vec(2, ""), vec(2, "")], "[F1, F2], N, constant tip forces (X, Z) on "
                            "master, slave") = ((0.0, 0.0), (0.0, 0.0))
    continuous_control: doc(bool, "analytic plant only: evaluate the control law in every RK4 stage") = False
    faults: doc(FaultConfig, "deliberate controller faults (testing bounds files)") = \
        field(default_factory=FaultConfig)
    controller: doc(ControllerConfig, "which control law runs (a table, or just the name)") = \
        field(default_factory=ControllerConfig)
    environment: doc(EnvironmentConfig, "objects the slave can touch (MuJoCo and Cosserat plants; none = "
                     "free space)") = \
        field(default_factory=EnvironmentConfig)
    sensing: doc(SensingConfig, "force sensing for the laws") = field(default_factory=SensingConfig)
    operator: doc(OperatorConfig, "the operator's hand (MuJoCo plant): a point mass on the master handle "
                  "(grip spring-damper) pulled toward scripted targets") = \
        field(default_factory=OperatorConfig)

    @property
    def plant_master(self) -> MasterParams:
        return self.plant.master if self.plant.master is not None else self.master

    @property
    def plant_slave(self) -> SlaveParams:
        return self.plant.slave if self.plant.slave is not None else self.slave

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.control_dt))

    @property
    def substeps(self) -> int:
        return int(round(self.control_dt / self.plant.physics_dt))
