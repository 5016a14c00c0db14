"""Typed, frozen scenario configuration (the fully resolved form of a scenario TOML file).

A scenario = controller side (nominal analytic models, gains, sub-tasks) + plant side (which plant,
its own parameters, which may differ from the nominal ones: that difference is the *mismatch*) +
trajectory, timing, noise and initial state.  Defaults reproduce the paper scenario (Sec. VI).

Loading/validation from TOML lives in `harness.config.load`; this module only defines the types.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from controllers.params import Gains, MasterParams, SlaveParams, SubtaskSpec

PLANTS = ("mujoco", "analytic", "cosserat")
ELASTIC_LAWS = ("analytic", "linear")
ACTUATIONS = ("servo", "torque")
INTEGRATORS = ("implicitfast", "implicit", "euler", "rk4")
ENV_KINDS = ("plane", "box", "sphere")
FORCE_MODES = ("exact", "sensed", "ignored")
NOISE_MODELS = ("per_channel", "per_vector")


@dataclass(frozen=True)
class TrajectoryConfig:
    """Desired master tip trajectory, paper eq. (40):
    x_d(t) = [cx + ax sin(w t), cz + az cos(w t)] in metres, relative to the master base."""

    center: tuple[float, float] = (0.0, 1.0)  # m
    amplitude: tuple[float, float] = (0.01, 0.01)  # m
    omega: float = 1.0  # rad/s


@dataclass(frozen=True)
class InitialState:
    """Initial conditions.  `master_offset` is added to the IK solution for x_d(0) (task-space, m).
    `slave_q2=None` picks equal straight-ish sections whose tip is at the master's initial tip."""

    master_offset: tuple[float, float] = (0.0, 0.0)  # m, task-space offset of the master tip
    master_elbow: int = -1  # sign of the elbow angle q_b of the IK solution (+1 or -1)
    slave_q2: tuple[float, ...] | None = None  # [d1,d2,d3,k1,k2,k3]; None = automatic
    slave_curvature: float = 1e-3  # 1/m, "curvatures near 0" used when slave_q2 is None


@dataclass(frozen=True)
class CosseratConfig:
    """Resolution and numerics of the Cosserat-rod plant (`plant.kind = "cosserat"`,
    harness.plant.cosserat): the material comes from [plant.slave] and the viscosities of [plant]."""

    elements_per_section: int = 10  # rod elements per section
    dt: float | str = "auto"  # s, rod time step; "auto" = largest control_dt / m below the stable step
    shear_factor: float = 10.0  # shear stiffness GA as a multiple of EA ("shear stiff")
    rotary_radius: float = 0.04  # m, disc radius of the rotary inertia when slave.slice_inertia = 0
    elastic_law: str = "analytic"  # "analytic" (CC-consistent energy) | "linear" (textbook rod)


@dataclass(frozen=True)
class PlantConfig:
    """The 'true' plant.  For `kind="mujoco"` the master/slave parameters below are what the MJCF is
    built from; the controller keeps using `Scenario.master` / `Scenario.slave` (nominal)."""

    kind: str = "mujoco"  # "mujoco" | "analytic" | "cosserat"
    master: MasterParams | None = None  # None = same as the nominal model (no mismatch)
    slave: SlaveParams | None = None  # None = same as the nominal model (no mismatch)
    actuation: str = "servo"  # "servo" | "torque"   (mujoco only)
    segments: int = 8  # rigid segments per section N (mujoco only)
    enforce_cc: bool = False  # CC equality constraints per section (option; README: default plant)
    physics_dt: float = 0.001  # s, MuJoCo timestep (analytic: RK4 step)
    integrator: str = "implicitfast"
    servo_frequency: float = 20.0  # Hz, natural frequency of the segment-joint servos
    servo_damping_ratio: float = 1.0  # servo damping ratio
    servo_feedforward: bool = True  # add the analytic T2 (mapped to segment joints) in servo mode
    actuation_delay: float = 0.0  # s, pure delay of the commands (multiple of control_dt)
    armature_fraction: float = 0.01  # segment-joint armature as a fraction of the section inertia
    scene_xml: str | None = None  # alternative scene MJCF (must include master + octarm base); None = mjcf/
    # material (Kelvin-Voigt) damping of the slave, per section, shared by the Cosserat rod and the
    # MuJoCo chain (joint damping eta_b / h, eta_a / h for segments of length h)
    bending_viscosity: tuple[float, float, float] = (0.1, 0.1, 0.1)  # eta_b, N m^2 s
    extension_viscosity: tuple[float, float, float] = (3.0, 3.0, 3.0)  # eta_a, N s
    cosserat: CosseratConfig = field(default_factory=CosseratConfig)  # [plant.cosserat]


@dataclass(frozen=True)
class FaultConfig:
    """Deliberate controller faults, for checking that a bounds file catches broken controllers
    (mutation testing of your CI bounds).  Defaults = no fault.
    e2_sign = -1 flips the sign of the coordination-error feedback in (18) (a sign error);
    null_space_scale multiplies phi_N (27) (0 = null-space term dropped, 1 = intact)."""

    e2_sign: int = 1
    null_space_scale: float = 1.0


@dataclass(frozen=True)
class ControllerConfig:
    """Which controller runs (see controllers/interface.py and harness/config/controller.py).

    name: a built-in ("paper" = the paper's law (12)-(33), compiled; `teleop controllers` lists the
    others), or a user class "path/to/file.py:ClassName" / "package.module:ClassName".
    params: the controller's own parameters (TOML values), validated by its class (`Params`) when the
    scenario is loaded through harness.api; the resolved config.toml spells out every one of them.
    step_timeout: s, the longest a Python controller's call may run (None: no limit); construction,
    reset and the first step may take at least 120 s (they may compile the nominal models)."""

    name: str = "paper"
    params: dict = field(default_factory=dict)
    step_timeout: float | None = 10.0


@dataclass(frozen=True)
class EnvObject:
    """One object of the environment the slave can touch (MuJoCo plant), in the slave's task plane:
    coordinates [X, Z] in metres relative to the Octarm base.  Contact is frictionless (condim 1) and
    linear: normal force = stiffness * penetration + damping (harness.plant.environment maps these to
    MuJoCo solref/solimp).  `plane`: infinite wall through `position` with unit `normal` pointing toward
    the arm (the free side); `box`: centre `position`, half sizes `size` [X, Z], rotated by `angle` about
    +y; `sphere`: centre `position`, radius size[0]."""

    name: str = "wall"
    kind: str = "plane"  # "plane" | "box" | "sphere"
    position: tuple[float, float] = (0.0, 1.2)  # m, slave task frame [X, Z]
    normal: tuple[float, float] = (0.0, -1.0)  # plane only: direction toward the free side (normalised)
    size: tuple[float, float] = (0.05, 0.05)  # m, box half sizes [X, Z]; sphere radius = size[0]
    angle: float = 0.0  # rad, box rotation about +y
    stiffness: float = 1.0e4  # N/m, normal contact stiffness, > 0
    damping_ratio: float = 1.0  # critical-damping fraction against the touching body's mass, >= 0


@dataclass(frozen=True)
class EnvironmentConfig:
    """Objects the slave's segments and tip can touch (none = the paper's free-space scenario)."""

    objects: tuple[EnvObject, ...] = ()


@dataclass(frozen=True)
class ForceSensingConfig:
    """What the controller gets as F = [F1, F2] in the laws (13), (17).  `exact`: the plant's true
    interaction forces (operator force at the master handle, constant + contact force at the slave tip);
    `sensed`: the same through noise (std, N, per component, seeded) -> first-order low-pass (cutoff
    Hz; none = no filter) -> pure delay (s, multiple of control_dt); `ignored`: F = 0 in the laws."""

    mode: str = "exact"  # "exact" | "sensed" | "ignored"
    noise_std: float = 0.0  # N, white noise per component (sensed mode)
    cutoff: float | None = None  # Hz, first-order low-pass cutoff; None = unfiltered (sensed mode)
    delay: float = 0.0  # s, multiple of control_dt (sensed mode)


@dataclass(frozen=True)
class SensingConfig:
    force: ForceSensingConfig = field(default_factory=ForceSensingConfig)


@dataclass(frozen=True)
class OperatorConfig:
    """The operator's hand on the master handle (MuJoCo plant): a point mass `mass` coupled to the
    master tip by a grip spring-damper (grip_stiffness, grip_damping) and pulled toward the scripted
    target by the arm's spring-damper (stiffness, damping).  targets = ((t, X, Z), ...): piecewise-linear
    target in the master task frame (s, m), held constant outside; empty = the initial tip position."""

    enabled: bool = False
    mass: float = 0.5  # kg, hand mass
    stiffness: float = 200.0  # N/m, arm stiffness toward the target
    damping: float = 20.0  # N s/m, arm damping (absolute hand velocity)
    grip_stiffness: float = 2000.0  # N/m, hand-handle coupling
    grip_damping: float = 40.0  # N s/m, hand-handle coupling
    targets: tuple[tuple[float, float, float], ...] = ()  # (t s, X m, Z m), times increasing


@dataclass(frozen=True)
class Scenario:
    """One fully resolved run."""

    name: str = "paper"
    duration: float = 20.0  # s
    control_dt: float = 0.001  # s (1 kHz), must be a multiple of plant.physics_dt
    snr_db: float | None = 40.0  # AWGN on fed-back states; None = no noise
    noise_model: str = "per_channel"  # SNR per signal (running power) | "per_vector" (per-step vector RMS)
    seed: int = 0
    transient: float = 5.0  # s, metrics (RMS/max) are taken after this time
    gains: Gains = field(default_factory=Gains)
    master: MasterParams = field(default_factory=MasterParams)  # nominal (controller) model
    slave: SlaveParams = field(default_factory=SlaveParams)  # nominal (controller) model
    subtask: SubtaskSpec = field(default_factory=SubtaskSpec)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    initial: InitialState = field(default_factory=InitialState)
    plant: PlantConfig = field(default_factory=PlantConfig)
    interaction_forces: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (0.0, 0.0))  # F1, F2 N
    continuous_control: bool = False  # analytic plant only: evaluate the control law in every RK4 stage
    faults: FaultConfig = field(default_factory=FaultConfig)  # deliberate faults (testing bounds)
    controller: ControllerConfig = field(default_factory=ControllerConfig)  # which control law runs
    environment: EnvironmentConfig = field(default_factory=EnvironmentConfig)  # contact objects (mujoco)
    sensing: SensingConfig = field(default_factory=SensingConfig)  # force sensing for the laws
    operator: OperatorConfig = field(default_factory=OperatorConfig)  # operator hand on the master

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
