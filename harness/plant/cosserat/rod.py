"""Cosserat-rod plant of the planar 3-section Octarm slave, on PyElastica.

API
---
    plant = CosseratSlave(params: SlaveParams, elements_per_section=10, dt=None,
                          material_damping=None, shear_factor=100.0, actuation="servo",
                          rotary_radius=0.04, elastic_law="analytic", muscle_radius=(0.16, 0.12, 0.09))
    plant.reset(q2, dq2=None)           # CC shape of q2 at rest-strain equilibrium (servo), time = 0
    plant.step(command (6,), duration, feedforward=None) -> bool   # False if the state diverged
    plant.sense() -> (q2 (6,), dq2 (6,))                 # least-squares CC fit of each section
    plant.tip() -> (2,)    plant.tip_velocity() -> (2,)   plant.centreline() -> (n_nodes, 3)
    plant.external_tip_force(F (2,))                     # constant tip force [FX, FZ], N (held)
    plant.section_nodes -> (4,) int                      # node indices of the section boundaries
    plant.time, plant.dt, plant.stable_dt                # s
    plant.stop                                           # None or an Event: set -> `step` raises RodStopped
    stable_dt(params, elements_per_section, ...)         # explicit-stability estimate, s
    check_steps_per_control(dt, control_dt) -> int       # rod steps per control step, ValueError above
                                                         # MAX_STEPS_PER_CONTROL
    material_damping_from_slave(params) -> (eta_b (3,), eta_a (3,))
    hinge_damping(eta_b, h), slide_damping(eta_a, h)     # MuJoCo chain joint damping from the material
Bad settings raise `ValueError` with one line naming the field, its value and the allowed range
(fields are named `plant.cosserat.<name>`).

Frames
------
The plane [X, Z] (Z up, base at the origin, tangent +Z, k > 0 bends toward +X) is embedded in
PyElastica's 3-D space as (X, 0, Z).  An element at tangent angle p (from +Z toward +X) has the
directors d1 = (cos p, 0, -sin p), d2 = +Y, d3 = (sin p, 0, cos p); a positive curvature is a
positive rotation about d2, i.e. the second component `kappa[1]` of PyElastica's curvature.
Gravity (gX, gZ) of `SlaveParams.gravity` is (gX, 0, gZ).  Loads stay in the plane, so the rod
stays planar (out-of-plane and twist components stay at round-off level).

Discretization and material
---------------------------
One `elastica.CosseratRod` with n = `elements_per_section` elements per section (3 n elements,
3 n + 1 nodes, section boundaries at nodes 0, n, 2n, 3n), rest element length l0_i = L0_i / n.
Per section i (SlaveParams fields: L0 = rest_lengths, Kb = bending_stiffness, Ke =
extension_stiffness, m = masses):

    EI_i = Kb_i                        (N m^2; twist GJ_i = 2/3 EI_i, Poisson 0.5)
    EA_i = Ke_i L0_i                   (N; so 1/2 EA (d/L0 - 1)^2 L0 = 1/2 Ke (d - L0)^2)
    GA_i = shear_factor * EA_i         (N; default 100: shear lowers the first mode by 0.08 %)
    rho A_i = m_i / L0_i               (kg/m of rest length: each section's mass uniform on it)
    rho I_i = slice_inertia_i or rho A_i rotary_radius^2 / 4   (kg m; rotary inertia, a disc)

Masses are lumped to nodes (half of each adjacent element), rotary inertia per element is
diag(rho I, rho I, 2 rho I) l0.  Hinges (Voronoi points) inside a section carry EI_i; the hinge at
a section boundary carries the series (harmonic) combination of the two half elements,
D0 / (l0_i / (2 EI_i) + l0_j / (2 EI_j)).

Elastic law.  PyElastica's own law (force S(sigma - sigma0)/e, moment B(kappa - kappa0)/e^3) is
not the standard one (see shared/api-notes.md).  The rod's `shear_matrix`/`bend_matrix` hold the
moduli above, and the whole elastic + damping + active load is computed by one compiled kernel
(`cosserat_rod.rod_loads`) from the strains that PyElastica's kernels compute
(`_compute_shear_stretch_strains`, `_compute_bending_twist_strains`, `_compute_dilatation_rate`):
the rod's built-in force law is never evaluated (computing it and subtracting would cancel two
large numbers).  With sigma, kappa the shear/stretch strain and curvature per *rest* length, e
the element stretch and eps the Voronoi stretch, the stored energy per rest length is

    elastic_law = "analytic" (default):  W = 1/2 (sigma - sigma0) S (sigma - sigma0)
                                            + 1/2 (kappa - kappa0) B (kappa - kappa0) / eps
    elastic_law = "linear":              W = 1/2 (sigma - sigma0) S (sigma - sigma0)
                                            + 1/2 (kappa - kappa0) B (kappa - kappa0)

so n = S(sigma - sigma0) (material frame) and m = B(kappa - kappa0)/eps (analytic) or
B(kappa - kappa0) (linear).  kappa / eps is the curvature per *current* length, so on a
constant-curvature section (kappa = k d / L0, eps = d / L0) the "analytic" energy is exactly
1/2 Kb d k^2 + 1/2 Ke (d - L0)^2, the energy of `controllers.slave`: the rod then differs from
the CC model only by its extra freedom (non-constant curvature, shear, rotary inertia), not by
its material.  Its d/d(eps) adds a chord tension -1/4 sum_adjacent (kappa - kappa0) B (kappa -
kappa0) / eps^2 per element (the bending-extension coupling of the analytic model: a pure
moment extends a section by Kb k^2 / (2 Ke)).  The "linear" law is the textbook rod (its
bending stiffness per current length is EI L0 / d).  Both give a pure end couple M a circular
arc of curvature M / EI and an axial force F an extension F / EA per unit length (tests).
The loads are assembled as in PyElastica's discretization: element force = difference of
Q^T n (+ chord tension); element torque = difference of the hinge couples + trapezoidal
kappa x m D0 + (sigma + e3) x n l0 + PyElastica's rotary-inertia terms (J w / e) x w and
J w de/dt / e^2.

Base clamp (second order).  Node 0 is held (its net force is set to zero, its velocity is zero),
and a half-element rotational spring joins element 0 to the base frame (tangent +Z): its
curvature is log(Q_0 Q_base^T) / (l0 / 2) with stiffness EI_1 and rest curvature that of
section 1, so the tangent is clamped at s = 0, not at s = l0 / 2.

Material damping (Kelvin-Voigt, internal)
-----------------------------------------
`material_damping = (eta_b (3,), eta_a (3,))`: bending viscosity eta_b (N m^2 s) and extension
viscosity eta_a (N s) per section, on the strain rates:

    m += eta_b d(kappa)/dt / eps   (analytic law; / 1 for linear),  d(kappa)/dt ~ (w_j+1 - w_j) / D0
    n += diag(eta_a, eta_a, eta_a) d(sigma)/dt,    d(sigma)/dt = Q (v_i+1 - v_i) / l0 - w x (sigma + e3)

(the shear viscosity equals eta_a).  It dissipates only strain rates (rigid motions are not
damped; it is not PyElastica's mass-proportional `AnalyticalLinearDamper`).  The bending part is
integrated implicitly (backward Euler over the kick, a tridiagonal solve per step) because, on
the light rotary inertia, an explicit viscous hinge would need steps ~1e-6 s; the extension
part is explicit (its limit is in `stable_dt`).  Dissipation on a CC section:
R = 1/2 eta_b d k'^2 + 1/2 (eta_a / L0) d'^2 (at fixed d, resp. k), so the analytic
generalized damping of SlaveParams maps as

    bending_damping c_k (N m^2 s on k-rates)  <->  eta_b = c_k / L0
    extension_damping c_d (N s/m on d-rates)  <->  eta_a = c_d L0      (`material_damping_from_slave`)

A chain of rigid segments of length h discretizing the same rod gets hinge damping eta_b / h
(N m s/rad, like its hinge stiffness EI / h) and slide damping eta_a / h (N s/m, like Ke L0 / h):
`hinge_damping`, `slide_damping`.  Default: eta_b = 0.1 N m^2 s and eta_a = 3 N s in every
section (`DEFAULT_ETA_B`, `DEFAULT_ETA_A`, = the scenario's plant.bending_viscosity /
extension_viscosity), i.e. c_k = 0.03 and c_d = 10 in SlaveParams units: first bending mode
1.28 Hz with a damping ratio of 11 % (`benchmarks/modal_cosserat.py`; README "Cosserat plant").

Actuation
---------
`actuation="servo"`: the command q2c = [d, k] becomes the rod's rest strains, the section's own
stiffness is the servo: rest stretch of the elements of section i sigma0_3 = (d_i / L0_i)
sinc(k_i h_i / 2) - 1 (h_i = d_i / n; the chord of an arc element, so the exact CC node set is the
discrete rest shape), rest curvature kappa0 = k_i d_i / L0_i inside the section, the rest-length
weighted mean at boundary hinges, that of section 1 at the base spring.  `feedforward` T2 is added
as in torque mode.
`actuation="torque"`: T2 = [T_d (N), T_k (N m)] acts as internal loads (virtual work with the
current fitted d, k, held during `step`): a uniform active bending couple T_k_i / d_i on the hinges
of section i (rest-length weighted mean at boundaries, full at the base spring) and an active axial
force T_d_i - k_i T_k_i / d_i on its elements (theta = k d: T_k dk = (T_k / d) dtheta -
(k T_k / d) dd, the README's MuJoCo torque mapping).  With the analytic law the static equilibrium
under T2 is exactly the analytic one.
`actuation="muscle"`: the command is the force p (6,) = [p+_1, p-_1, ...] (N, >= 0 pushing) of the two
extensor groups of each section at lateral offsets s = +r_i, -r_i (`muscle_radius`, along d1); a fibre
of length l_s = int (1 - s kappa) ds does the virtual work of an axial force p and a couple -s p on
every cross-section of its section (`kernels.muscle_loads`): on a CC section, the generalized force
p (1 - s k, -s d) of the MuJoCo chain's fibres d (1 - s k) (`harness.plant.chain_map.muscle_commands`).
The force dynamics and limits are the plant's (`harness.plant.cosserat.plant`).

Sensing
-------
`sense()`: per section, the chords of its n elements (lengths c_j, angles phi_j from +Z toward
+X, unwrapped) are fitted by a circle: phi_j = phi_0 + k s_j (least squares in s_j, the arc length
at the chord's mid-arc), with the chord-to-arc correction a_j = 2 asin(k c_j / 2) / k iterated
(16 times) with the fit; d = sum a_j.  On points sampled on an exact arc this recovers d and k to
round-off.  Rates, from the node velocities: k' = sum w_j (phi_j' - k s_j') with w the least-squares
weights, a_j' = (da/dc) c_j' + (da/dk) k', d' = sum a_j' (3 fixed-point passes; exact on CC
data, first order in the residual otherwise).

Time stepping
-------------
Position Verlet (PyElastica's `PositionVerlet` order: half drift, loads, kick, half drift) with
PyElastica's update kernels, compiled into one loop (`cosserat_rod.run_steps`); `stepper =
"pyelastica"` runs `PositionVerlet.step_single_instance` on the PyElastica memory block instead
(same numbers, slower; used to check the compiled loop).  The default dt is the largest 1 ms / m below
`stable_dt`.

The explicit step (`stable_dt`), refused configurations, interrupts and divergence:
`harness.plant.cosserat.limits`.
"""

from __future__ import annotations

import math

import elastica as ea
import numpy as np
from elastica.timestepper.symplectic_steppers import PositionVerlet

from controllers.cc import backbone_points
from controllers.params import SlaveParams
from harness.plant.cosserat import kernels as kr
from harness.plant.cosserat.limits import (
    BATCH_STEPS,
    DEFAULT_ELEMENTS,
    DEFAULT_ETA_A,
    DEFAULT_ETA_B,
    DEFAULT_ROTARY_RADIUS,
    DEFAULT_SHEAR_FACTOR,
    EXPLODING_LENGTHS,
    MAX_STEPS_PER_CONTROL,
    RodStopped,
    _material,
    auto_dt,
    check_steps_per_control,
    stable_dt,
)

FIT_ITERATIONS = 16
_BASE_DT = 1e-3


def _err(name: str, value, rng: str) -> ValueError:
    return ValueError(f"plant.cosserat.{name} = {value!r}: {rng}")


def material_damping_from_slave(params: SlaveParams) -> tuple[np.ndarray, np.ndarray]:
    """(eta_b, eta_a) equivalent to SlaveParams' generalized damping: c_k / L0 and c_d L0."""
    L0 = np.asarray(params.rest_lengths)
    return np.asarray(params.bending_damping) / L0, np.asarray(params.extension_damping) * L0


def hinge_damping(eta_b, h):
    """Hinge damping (N m s/rad) between two rigid segments of length h of a rod of viscosity eta_b."""
    return np.asarray(eta_b, dtype=float) / np.asarray(h, dtype=float)


def slide_damping(eta_a, h):
    """Slide damping (N s/m) of a segment of rest length h of a rod of extension viscosity eta_a."""
    return np.asarray(eta_a, dtype=float) / np.asarray(h, dtype=float)


def _rot_y(p: float) -> np.ndarray:
    c, s = math.cos(p), math.sin(p)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


class _Sim(ea.BaseSystemCollection):
    pass


class CosseratSlave:
    """Planar 3-section Octarm as one PyElastica Cosserat rod (see the module docstring)."""

    def __init__(self, params: SlaveParams, elements_per_section: int = DEFAULT_ELEMENTS,
                 dt: float | None = None, material_damping=None,
                 shear_factor: float = DEFAULT_SHEAR_FACTOR, actuation: str = "servo",
                 rotary_radius: float = DEFAULT_ROTARY_RADIUS, elastic_law: str = "analytic",
                 stepper: str = "numba", muscle_radius=(0.16, 0.12, 0.09)) -> None:
        if not isinstance(params, SlaveParams):
            raise _err("params", type(params).__name__, "must be a controllers.params.SlaveParams")
        n = elements_per_section
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and 2 <= n <= 200):
            raise _err("elements_per_section", n, "must be an integer in [2, 200]")
        n = int(n)
        if actuation not in ("servo", "torque", "muscle"):
            raise _err("actuation", actuation, "must be 'servo', 'torque' or 'muscle'")
        if elastic_law not in ("analytic", "linear"):
            raise _err("elastic_law", elastic_law, "must be 'analytic' or 'linear'")
        if stepper not in ("numba", "pyelastica"):
            raise _err("stepper", stepper, "must be 'numba' or 'pyelastica'")
        for name, v in (("shear_factor", shear_factor), ("rotary_radius", rotary_radius)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise _err(name, v, "must be a finite number > 0")
        for name, v in (("slave.bending_stiffness", params.bending_stiffness),
                        ("slave.extension_stiffness", params.extension_stiffness)):
            if min(v) <= 0:
                raise _err(name, tuple(v), "every entry must be > 0 (moduli of the rod)")
        if material_damping is None:
            eta_b, eta_a = np.full(3, DEFAULT_ETA_B), np.full(3, DEFAULT_ETA_A)
        else:
            try:
                eta_b, eta_a = (np.broadcast_to(np.asarray(x, dtype=float), (3,)).copy()
                                for x in material_damping)
            except (TypeError, ValueError):
                raise _err("material_damping", material_damping,
                           "must be (eta_b, eta_a), each a number or 3 numbers >= 0") from None
            if not (np.all(np.isfinite(eta_b)) and np.all(np.isfinite(eta_a))
                    and eta_b.min() >= 0 and eta_a.min() >= 0):
                raise _err("material_damping", material_damping, "every entry must be finite and >= 0")
        self.stable_dt = stable_dt(params, n, shear_factor, rotary_radius, eta_a)
        if dt is None:
            dt = auto_dt(_BASE_DT, self.stable_dt)
            check_steps_per_control(dt, _BASE_DT)
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise _err("dt", dt, "must be a finite number > 0")
        if dt > self.stable_dt:
            raise _err("dt", dt, f"too large for {n} elements per section, must be <= "
                       f"{self.stable_dt:.3g} s")
        self.params = params
        self.n = n
        self.dt = float(dt)
        self.actuation = actuation
        self.muscle_radius = np.asarray(muscle_radius, dtype=float)
        self.eta_b, self.eta_a = eta_b, eta_a
        self.shear_factor = float(shear_factor)
        self.analytic_law = elastic_law == "analytic"
        self.stepper = stepper
        self.stop = None  # an Event (or anything with is_set()): set -> `step` raises RodStopped
        self._far = EXPLODING_LENGTHS * float(np.sum(params.rest_lengths))  # m, exploding-state radius
        self.section_nodes = np.array([0, n, 2 * n, 3 * n], dtype=np.int64)
        self._build(rotary_radius)
        self.reset(np.concatenate([params.rest_lengths, np.zeros(3)]))

    # --- construction -------------------------------------------------------------------------------
    def _build(self, rotary_radius: float) -> None:
        p, n = self.params, self.n
        L0, EI, EA, GA, rhoA, rhoI = _material(p, self.shear_factor, rotary_radius)
        ne, nv, nn = 3 * n, 3 * n - 1, 3 * n + 1
        sec = np.repeat(np.arange(3), n)  # section of each element
        l0 = (L0 / n)[sec]
        z = np.concatenate([[0.0], np.cumsum(l0)])
        pos = np.zeros((3, nn))
        pos[2] = z
        rod = ea.CosseratRod.straight_rod(
            ne, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), float(z[-1]),
            0.01, 1000.0, youngs_modulus=1e6, position=pos)
        sim = _Sim()
        sim.append(rod)
        sim.finalize()
        b = next(iter(sim.final_systems()))
        self._sim, self._rod, self._b = sim, rod, b
        # mass lumped to nodes, rotary inertia per element
        me = (np.asarray(p.masses) / n)[sec]
        b.mass[:] = 0.0
        b.mass[:-1] += 0.5 * me
        b.mass[1:] += 0.5 * me
        J = np.zeros((3, 3, ne))
        invJ = np.zeros((3, 3, ne))
        jd = np.stack([rhoI[sec], rhoI[sec], 2.0 * rhoI[sec]]) * l0
        for i in range(3):
            J[i, i] = jd[i]
            invJ[i, i] = 1.0 / jd[i]
        b.mass_second_moment_of_inertia[:] = J
        b.inv_mass_second_moment_of_inertia[:] = invJ
        b.shear_matrix[:] = 0.0
        b.shear_matrix[0, 0] = GA[sec]
        b.shear_matrix[1, 1] = GA[sec]
        b.shear_matrix[2, 2] = EA[sec]
        # hinges: inside a section EI_i, at boundaries the series combination of the two half elements
        D0 = b.rest_voronoi_lengths.copy()
        Bh = np.empty(nv)
        etah = np.empty(nv)
        for j in range(nv):
            a, c = sec[j], sec[j + 1]
            Bh[j] = D0[j] / (0.5 * l0[j] / EI[a] + 0.5 * l0[j + 1] / EI[c])
            eb = (self.eta_b[a], self.eta_b[c])
            etah[j] = (D0[j] / (0.5 * l0[j] / eb[0] + 0.5 * l0[j + 1] / eb[1])
                       if min(eb) > 0 else 0.0)
        b.bend_matrix[:] = 0.0
        b.bend_matrix[0, 0] = Bh
        b.bend_matrix[1, 1] = Bh
        b.bend_matrix[2, 2] = Bh * (2.0 / 3.0)
        self._eta_v = np.stack([etah, etah, etah * (2.0 / 3.0)])
        ea_e = self.eta_a[sec]
        self._eta_e = np.stack([ea_e, ea_e, ea_e])
        self._base_B = np.array([EI[0], EI[0], EI[0] * 2.0 / 3.0])
        self._base_eta = np.array([self.eta_b[0], self.eta_b[0], self.eta_b[0] * 2.0 / 3.0])
        self._base_Q = np.eye(3)
        self._base_kappa0 = np.zeros(3)
        self._sec, self._l0, self._D0 = sec, l0, D0
        g3 = np.array([p.gravity[0], 0.0, p.gravity[1]])
        self._node_force = np.ascontiguousarray(np.outer(g3, b.mass))
        self._tip_force = np.zeros(3)
        self._act_n = np.zeros(ne)
        self._act_m = np.zeros((3, nv))
        self._act_m_base = np.zeros(3)
        self._act_q2, self._act_dq2 = np.zeros(6), np.zeros(6)  # the fit `_set_active` works at
        self._L0 = np.asarray(p.rest_lengths, dtype=float)
        self._law = 1 if self.analytic_law else 0
        self._objs = np.zeros((0, 6))  # environment contact (`set_contacts`, harness.plant.rod_contact)
        self._cdamp = np.zeros((0, ne + 2))
        self.f_contact = np.zeros((3, ne + 1))  # N, contact force on each node (last substep)
        self._fit_valid = False  # `sense_into`: the CC fit of the current rod state is cached
        self._fit_q2, self._fit_dq2 = np.zeros(6), np.zeros(6)
        self._fit_xz, self._fit_vxz = np.zeros((ne + 1, 2)), np.zeros((ne + 1, 2))  # node X, Z and rates
        if self.stepper == "pyelastica":
            self._verlet = PositionVerlet()
            b.compute_internal_forces_and_torques = self._compute_loads  # instance override

    def _load_args(self):
        b = self._b
        return (b.position_collection, b.velocity_collection, b.director_collection, b.omega_collection,
                b.mass_second_moment_of_inertia, b.volume, b.lengths, b.tangents, b.radius,
                b.rest_lengths, b.rest_voronoi_lengths, b.dilatation, b.voronoi_dilatation, b.sigma,
                b.kappa, b.dilatation_rate, b.rest_sigma, b.rest_kappa, b.shear_matrix, b.bend_matrix,
                self._eta_e, self._eta_v, self._base_Q, self._base_B, self._base_eta, self._base_kappa0,
                self._act_n, self._act_m, self._act_m_base, self._node_force, self._tip_force, self._law,
                self._objs, self._cdamp, self.f_contact)

    def set_contacts(self, objs: np.ndarray, cdamp: np.ndarray) -> None:
        """Environment objects acting on the nodes from now on: objs (no, 6), cdamp (no, nn + 1) as in
        `cosserat_rod.contact_forces`."""
        self._objs = np.ascontiguousarray(objs, dtype=float)
        self._cdamp = np.ascontiguousarray(cdamp, dtype=float)

    def _compute_loads(self, time=0.0) -> None:
        b = self._b
        kr.rod_loads(*self._load_args(), self.dt, b.internal_forces, b.internal_torques,
                     b.external_forces, b.external_torques)

    # --- commands -----------------------------------------------------------------------------------
    def _set_rest(self, q2c: np.ndarray) -> None:
        kr.rest_strains(q2c, self.n, self._L0, self._sec, self._l0, self._b.rest_sigma, self._b.rest_kappa,
                        self._base_kappa0)

    def _set_active(self, T2: np.ndarray | None) -> None:
        if T2 is None:
            self._act_n[:] = 0.0
            self._act_m[:] = 0.0
            self._act_m_base[:] = 0.0
            return
        self.sense_into(self._act_q2, self._act_dq2)
        kr.active_loads(T2, self._act_q2, self._sec, self._l0, self._act_n, self._act_m, self._act_m_base)

    @staticmethod
    def _vec6(name: str, v) -> np.ndarray:
        a = np.asarray(v, dtype=float).ravel()
        if a.shape != (6,) or not np.isfinite(a).all():
            raise _err(name, v, "must be 6 finite numbers [d1, d2, d3, k1, k2, k3]")
        return a

    # --- public API ---------------------------------------------------------------------------------
    def reset(self, q2, dq2=None) -> None:
        """Place the rod on the CC shape of q2 (nodes exactly on the arcs) with CC rates dq2 (default 0);
        in servo mode the rest strains become q2 (so it is at equilibrium without gravity)."""
        q2 = self._vec6("q2", q2)
        if np.any(q2[:3] <= 0):
            raise _err("q2", tuple(q2), "section lengths must be > 0")
        dq2 = np.zeros(6) if dq2 is None else self._vec6("dq2", dq2)
        b = self._b
        self._fit_valid = False  # the rod is moved: a cached CC fit is stale
        xz, ang = self._cc(q2)
        b.position_collection[:] = 0.0
        b.position_collection[0] = xz[:, 0]
        b.position_collection[2] = xz[:, 1]
        for j, a in enumerate(ang):
            b.director_collection[:, :, j] = _rot_y(a)
        b.velocity_collection[:] = 0.0
        b.omega_collection[:] = 0.0
        if np.any(dq2 != 0):
            dx = np.zeros_like(xz)
            da = np.zeros_like(ang)
            for i in range(6):
                if dq2[i] == 0:
                    continue
                eps = 1e-6 * max(1.0, abs(q2[i]))
                qp, qm = q2.copy(), q2.copy()
                qp[i] += eps
                qm[i] -= eps
                xp, ap = self._cc(qp)
                xm, am = self._cc(qm)
                dx += (xp - xm) / (2 * eps) * dq2[i]
                da += (ap - am) / (2 * eps) * dq2[i]
            b.velocity_collection[0] = dx[:, 0]
            b.velocity_collection[2] = dx[:, 1]
            b.omega_collection[1] = da
        self._tip_force[:] = 0.0
        self.f_contact[:] = 0.0
        self._set_active(None)
        self._set_rest(q2 if self.actuation == "servo" else
                       np.concatenate([self.params.rest_lengths, np.zeros(3)]))
        self.time = 0.0
        self._steps = 0

    def _cc(self, q2):
        """Nodes [X, Z] (3 n + 1, 2) of the CC shape q2 at uniform arc-length steps d_i / n within each
        section (exactly on the arcs: `controllers.cc.backbone_points`) and the element chord angles (3 n,)
        (from +Z toward +X: the tangent at the element's middle)."""
        q2 = np.asarray(q2, dtype=float)
        xz = np.empty((3 * self.n + 1, 2))
        backbone_points(q2, self.n, xz)
        ang = np.empty(3 * self.n)
        phi = 0.0
        for s in range(3):
            dphi = q2[3 + s] * (q2[s] / self.n)
            for m in range(self.n):
                ang[s * self.n + m] = phi + 0.5 * dphi
                phi += dphi
        return xz, ang

    def external_tip_force(self, F) -> None:
        """Hold a constant force [FX, FZ] (N) on the tip node from now on (until changed)."""
        F = np.asarray(F, dtype=float).ravel()
        if F.shape != (2,) or not np.all(np.isfinite(F)):
            raise _err("tip_force", F.tolist(), "must be 2 finite numbers [FX, FZ] in N")
        self._tip_force[:] = (F[0], 0.0, F[1])

    def step(self, command, duration: float, feedforward=None) -> bool:
        """Advance by `duration` (a multiple of dt) with the command held: servo: q2 command (rest
        strains, plus `feedforward` T2 if given); torque: T2; muscle: the group forces p (N).  Returns
        False if the state diverged."""
        command = self._vec6("command", command)
        m = round(duration / self.dt)
        tol = 1e-9 * max(1.0, duration)
        if not (math.isfinite(duration) and m >= 1 and abs(m * self.dt - duration) <= tol):
            raise _err("duration", duration, f"must be a positive multiple of dt = {self.dt:.6g} s")
        if self.actuation == "servo":
            if (command[:3] <= 0).any():
                raise _err("command", tuple(command), "commanded section lengths must be > 0")
            self._set_rest(command)
            self._set_active(None if feedforward is None else self._vec6("feedforward", feedforward))
        elif self.actuation == "muscle":
            kr.muscle_loads(command, self.muscle_radius, self._sec, self._l0, self._act_n, self._act_m,
                            self._act_m_base)
        else:
            self._set_active(command)
        self._fit_valid = False  # the rod moves: a cached CC fit is stale
        left = m
        while left > 0:
            n = min(left, BATCH_STEPS)
            try:
                ok = self._run(n) and self._sane()
            except ArithmeticError:  # ZeroDivisionError on a collapsed element, FloatingPointError, ...
                ok = False
            left -= n
            self._steps += n
            self.time = self._steps * self.dt
            if not ok:
                return False
            if self.stop is not None and self.stop.is_set():
                raise RodStopped(f"rod stopped at t = {self.time:.6g} s")
        return True

    def _run(self, n: int) -> bool:
        """n rod steps; False if the positions are not finite."""
        b = self._b
        if self.stepper == "numba":
            return kr.run_steps(n, self.dt, b.position_collection, b.velocity_collection,
                                b.director_collection, b.omega_collection, b.acceleration_collection,
                                b.alpha_collection, b.mass,
                                b.mass_second_moment_of_inertia, b.inv_mass_second_moment_of_inertia,
                                *self._load_args()[5:], b.internal_forces, b.internal_torques,
                                b.external_forces, b.external_torques)
        t = np.float64(self.time)
        for _ in range(n):
            t = self._verlet.step_single_instance(b, t, np.float64(self.dt))
        return True

    def _sane(self) -> bool:
        """Node positions, velocities and element angular velocities finite, every node within
        EXPLODING_LENGTHS rod lengths of the base."""
        b = self._b
        pos = b.position_collection
        if not (np.isfinite(pos).all() and np.isfinite(b.velocity_collection).all()
                and np.isfinite(b.omega_collection).all()):
            return False
        return float(np.abs(pos).max()) <= self._far

    def sense(self) -> tuple[np.ndarray, np.ndarray]:
        """(q2, dq2): least-squares CC fit of each section's nodes and its first-order rates."""
        q2, dq2 = np.empty(6), np.empty(6)
        self.sense_into(q2, dq2)
        return q2, dq2

    def sense_into(self, q2: np.ndarray, dq2: np.ndarray) -> None:
        """`sense` into q2, dq2 (6,).  The fit is kept until the rod moves (`step`, `reset`): the plant's
        sensing and the servo feed-forward of the next step fit the same state once, not twice."""
        if not self._fit_valid:
            b = self._b
            kr.fit_rod(b.position_collection, b.velocity_collection, self._fit_xz, self._fit_vxz,
                       self.section_nodes, FIT_ITERATIONS, self._fit_q2, self._fit_dq2)
            self._fit_valid = True
        q2[:] = self._fit_q2
        dq2[:] = self._fit_dq2

    def tip(self) -> np.ndarray:
        """Tip node [X, Z] (2,), m."""
        return self._b.position_collection[[0, 2], -1].copy()

    def tip_velocity(self) -> np.ndarray:
        return self._b.velocity_collection[[0, 2], -1].copy()

    def centreline(self) -> np.ndarray:
        """Node positions (n_nodes, 3) in 3-D (X, 0, Z), base first (the recording's 3-D view)."""
        return self._b.position_collection.T.copy()


__all__ = ["BATCH_STEPS", "DEFAULT_ELEMENTS", "DEFAULT_ETA_A", "DEFAULT_ETA_B", "MAX_STEPS_PER_CONTROL",
           "CosseratSlave", "RodStopped", "auto_dt", "check_steps_per_control", "hinge_damping",
           "material_damping_from_slave", "slide_damping", "stable_dt"]
