"""Cosserat-rod plant of the planar 3-section Octarm slave on PyElastica (`CosseratSlave`); model,
frames, actuation, sensing and stepping: docs/plants.md, "The Cosserat rod's model".
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


def _rot_y(p: float) -> np.ndarray:
    c, s = math.cos(p), math.sin(p)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


class _Sim(ea.BaseSystemCollection):
    pass


class CosseratSlave:
    """Planar 3-section Octarm as one PyElastica Cosserat rod (docs/plants.md)."""

    def __init__(self, params: SlaveParams, elements_per_section: int = DEFAULT_ELEMENTS,
                 dt: float | None = None, material_damping=(DEFAULT_ETA_B, DEFAULT_ETA_A),
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
        for name in ("bending_stiffness", "extension_stiffness", "rest_lengths", "masses", "slice_inertia"):
            v = np.asarray(getattr(params, name), dtype=float)
            lo = 0.0 if name == "slice_inertia" else np.nextafter(0.0, 1.0)
            if not (np.all(np.isfinite(v)) and v.min() >= lo):
                raise _err(f"slave.{name}", tuple(v.tolist()),
                           f"every entry must be finite and {'>=' if lo == 0.0 else '>'} 0")
        try:
            eta_b, eta_a = (np.broadcast_to(np.asarray(x, float), (3,)).copy() for x in material_damping)
        except (TypeError, ValueError):
            raise _err("material_damping", material_damping,
                       "must be (eta_b, eta_a), each a number or 3 numbers >= 0") from None
        if not (np.all(np.isfinite(eta_b)) and np.all(np.isfinite(eta_a)) and eta_b.min() >= 0
                and eta_a.min() >= 0):
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
        d3 = np.arange(3)  # the diagonal of each element's 3 x 3 matrices
        jd = np.stack([rhoI[sec], rhoI[sec], 2.0 * rhoI[sec]]) * l0
        for M, v in ((b.mass_second_moment_of_inertia, jd), (b.inv_mass_second_moment_of_inertia, 1.0 / jd),
                     (b.shear_matrix, np.stack([GA[sec], GA[sec], EA[sec]]))):
            M[:] = 0.0
            M[d3, d3] = v
        # hinges: inside a section EI_i, at boundaries the series combination of the two half elements
        D0 = b.rest_voronoi_lengths.copy()
        Bh = D0 / (0.5 * l0[:-1] / EI[sec[:-1]] + 0.5 * l0[1:] / EI[sec[1:]])
        e0, e1 = self.eta_b[sec[:-1]], self.eta_b[sec[1:]]
        with np.errstate(divide="ignore"):
            etah = np.where(np.minimum(e0, e1) > 0, D0 / (0.5 * l0[:-1] / e0 + 0.5 * l0[1:] / e1), 0.0)
        b.bend_matrix[:] = 0.0
        b.bend_matrix[d3, d3] = np.stack([Bh, Bh, Bh * (2.0 / 3.0)])
        self._eta_v = np.stack([etah, etah, etah * (2.0 / 3.0)])
        self._eta_e = np.stack([self.eta_a[sec]] * 3)
        self._base_B = np.array([EI[0], EI[0], EI[0] * 2.0 / 3.0])
        self._base_eta = np.array([self.eta_b[0], self.eta_b[0], self.eta_b[0] * 2.0 / 3.0])
        self._base_Q = np.eye(3)
        self._base_kappa0 = np.zeros(3)
        self._sec, self._l0 = sec, l0
        g3 = np.array([p.gravity[0], 0.0, p.gravity[1]])
        self._node_force = np.ascontiguousarray(np.outer(g3, b.mass))
        self._tip_force = np.zeros(3)
        self._act_n, self._act_m, self._act_m_base = np.zeros(ne), np.zeros((3, nv)), np.zeros(3)
        self._act_q2, self._act_dq2 = np.zeros(6), np.zeros(6)  # the fit `_set_active` works at
        self._L0 = np.asarray(p.rest_lengths, dtype=float)
        self._law = 1 if self.analytic_law else 0
        self._objs = np.zeros((0, 6))  # environment contact (`set_contacts`, harness.plant.cosserat.contact)
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
        `kernels.contact_forces`."""
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
            for a in (self._act_n, self._act_m, self._act_m_base):
                a[:] = 0.0
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
            for i in np.flatnonzero(dq2):  # central differences of the CC shape
                e = 1e-6 * max(1.0, abs(q2[i])) * (np.arange(6) == i)
                eps = e[i]
                (xp, ap), (xm, am) = self._cc(q2 + e), self._cc(q2 - e)
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
        """Nodes [X, Z] (3 n + 1, 2) of the CC shape q2 at arc-length steps d_i / n (on the arcs) and the
        element chord angles (3 n,) from +Z toward +X."""
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
        """Advance by `duration` (a multiple of dt) holding the command: servo: q2 (rest strains, plus
        `feedforward` T2); torque: T2; muscle: the group forces p (N).  False if the state diverged."""
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
                self._run(n)
                ok = self._sane()
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

    def _run(self, n: int) -> None:
        """n rod steps (`_sane` checks the state after them)."""
        b = self._b
        if self.stepper == "numba":
            kr.run_steps(n, self.dt, b.position_collection, b.velocity_collection, b.director_collection,
                         b.omega_collection, b.acceleration_collection, b.alpha_collection, b.mass,
                         b.mass_second_moment_of_inertia, b.inv_mass_second_moment_of_inertia,
                         *self._load_args()[5:], b.internal_forces, b.internal_torques, b.external_forces,
                         b.external_torques)
            return
        t = np.float64(self.time)
        for _ in range(n):
            t = self._verlet.step_single_instance(b, t, np.float64(self.dt))

    def _sane(self) -> bool:
        """Nodes and rates finite, every node within EXPLODING_LENGTHS rod lengths of the base."""
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
        """`sense` into q2, dq2 (6,); the fit is cached until the rod moves (`step`, `reset`)."""
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

    def centreline(self) -> np.ndarray:
        """Node positions (n_nodes, 3) in 3-D (X, 0, Z), base first (the recording's 3-D view)."""
        return self._b.position_collection.T.copy()


__all__ = ["BATCH_STEPS", "DEFAULT_ELEMENTS", "DEFAULT_ETA_A", "DEFAULT_ETA_B", "MAX_STEPS_PER_CONTROL",
           "CosseratSlave", "RodStopped", "auto_dt", "check_steps_per_control",
           "material_damping_from_slave", "stable_dt"]
