"""The Cosserat-rod plant of a scenario (`CosseratPlant`, a `SteppedPlant`): the rod slave and the
analytic master (eq. 1, RK4 steps <= 1 ms).  Actuation, sensing, forces, geometry: docs/plants.md.
"""

from __future__ import annotations

import math
import types

import numpy as np
from numba import njit

from controllers import master as master_model
from controllers import slave as slave_model
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.plant.chain_map import muscle_commands
from harness.plant.cosserat import contact as rod_contact
from harness.plant.cosserat.rod import CosseratSlave, auto_dt, check_steps_per_control, stable_dt
from harness.plant.initial import InitialStateError, initial_state

MASTER_BASE = np.array([0.0, -0.3, 0.0])  # m, world (as mjcf/master.xml)
SLAVE_BASE = np.array([0.0, 0.3, 0.0])  # m, world (as mjcf/octarm_base.xml)
MASTER_MAX_H = 1e-3  # s, largest master RK4 step

_master_kernel = njit(cache=True)(master_model.master_kernel)
# master_accel compiled with its callee compiled (a copy of the function bound to _master_kernel)
_accel = master_model.master_accel
_master_accel = njit(cache=True)(types.FunctionType(_accel.__code__, {**_accel.__globals__,
                                                                      "master_kernel": _master_kernel}))
master_points = njit(cache=True)(master_model.master_points)
_elastic_kernel = njit(cache=True)(slave_model.elastic_kernel)


@njit(cache=True)
def master_rk4(mpk, s, T1, F1, h, nsub):
    """nsub classical RK4 steps of h (s) of the master, in place on s (4,) = [q1, dq1], T1 (2,) N m and
    the tip force F1 (2,) N held.  False on a singular mass matrix or a non-finite state."""
    K, tmp = np.empty((4, 4)), np.empty(4)
    c = (0.5 * h, 0.5 * h, h)  # the stage offsets
    for _ in range(nsub):
        ok = _master_accel(mpk, s, T1, F1, K[0])
        for st in range(3):
            for i in range(4):
                tmp[i] = s[i] + c[st] * K[st, i]
            ok = _master_accel(mpk, tmp, T1, F1, K[st + 1]) and ok
        if not ok:
            return False
        for i in range(4):
            s[i] += h / 6.0 * (K[0, i] + 2.0 * K[1, i] + 2.0 * K[2, i] + K[3, i])
            if not np.isfinite(s[i]):
                return False
    return True


@njit(cache=True)
def feedforward(T2, q2, spk, out):
    """Servo feed-forward out (6,) = T2 - dV/dq2 at q2 (6,) = [d, k], V = sum 1/2 Kb d k^2 + 1/2 Ke (d - L0)^2
    the plant slave's CC elastic energy (`controllers.slave.elastic_kernel`; spk: SlaveParams.packed())."""
    E = np.empty(6)
    _elastic_kernel(spk, q2, E)
    for i in range(6):
        out[i] = T2[i] - E[i]


def _field_of(msg: str, scn: Scenario) -> str:
    """Scenario field names for CosseratSlave's messages."""
    slave = "plant.slave." if scn.plant.slave is not None else "slave."
    return msg.replace("plant.cosserat.slave.", slave).replace("plant.cosserat.actuation", "plant.actuation")


def rod_dt(scn: Scenario) -> tuple[float, float]:
    """(rod time step, stable_dt) of the scenario, s; ConfigError naming plant.cosserat.dt if the
    set step is too large for the elements or does not divide control_dt."""
    c = scn.plant.cosserat
    p = scn.plant_slave
    for name in ("bending_stiffness", "extension_stiffness"):
        v = getattr(p, name)
        if min(v) <= 0:
            field = ("plant.slave." if scn.plant.slave is not None else "slave.") + name
            raise ConfigError.field(field, list(v), "every entry must be > 0 for the Cosserat plant "
                                    "(moduli of the rod)")
    sdt = stable_dt(p, c.elements_per_section, c.shear_factor, c.rotary_radius,
                    np.asarray(scn.plant.extension_viscosity, dtype=float))
    cdt = scn.control_dt
    if c.dt == "auto":
        dt = auto_dt(cdt, sdt)
    else:
        dt = float(c.dt)
        if dt > sdt:
            raise ConfigError.field("plant.cosserat.dt", c.dt, f"too large for {c.elements_per_section} "
                                    f"elements per section: must be <= {sdt:.4g} s (or \"auto\")")
        m = round(cdt / dt)
        if m < 1 or abs(m * dt - cdt) > 1e-9 * cdt:
            raise ConfigError.field("plant.cosserat.dt", c.dt,
                                    f"must divide control_dt = {cdt:g} s into an integer number of steps")
    try:
        check_steps_per_control(dt, cdt)
    except ValueError as exc:
        raise ConfigError.field("plant.cosserat.dt", c.dt, str(exc).split(": ", 1)[1]) from None
    return dt, sdt


class CosseratPlant:
    """Rod slave + analytic rigid master, stepped from Python (`SteppedPlant`)."""

    kind = "cosserat"

    def __init__(self, scn: Scenario) -> None:
        c = scn.plant.cosserat
        dt, self.stable_dt = rod_dt(scn)
        try:
            self.slave = CosseratSlave(
                scn.plant_slave, c.elements_per_section, dt=dt,
                material_damping=(scn.plant.bending_viscosity, scn.plant.extension_viscosity),
                shear_factor=c.shear_factor, actuation=scn.plant.actuation,
                rotary_radius=c.rotary_radius, elastic_law=c.elastic_law,
                muscle_radius=scn.plant.muscle_radius)
        except ValueError as exc:
            raise ConfigError(_field_of(str(exc), scn), path="plant.cosserat") from None
        self.actuation = scn.plant.actuation
        self.physics_dt = self.slave.dt
        self.feedforward = scn.plant.servo_feedforward
        self.mpk = master_model.packed(scn.plant_master)
        self.F1, self.F2 = np.array(scn.interaction_forces, dtype=float)
        self._m = np.zeros(4)  # master [q1, dq1]
        self._T1, self._T2, self._q_ref, self._ff = np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6)
        self._spk = scn.plant_slave.packed()
        self._fmax = np.repeat(np.asarray(scn.plant.muscle_max_force, dtype=float), 2)
        self._tau = np.repeat(np.asarray(scn.plant.muscle_time_constant, dtype=float), 2)
        self.muscle_force = np.zeros(6)  # N, muscle group forces (the actuator state)
        self._ctrl = np.zeros(6)  # N, muscle commands clipped to [0, F_max]
        self.saturated = 0  # muscle group-steps commanded outside [0, F_max]
        nn = 3 * self.slave.n + 1
        self._geo = {"centreline": np.zeros((nn, 3)), "sections": np.zeros((4, 3)),
                     "master": np.zeros((3, 3))}
        self._q2, self._dq2 = np.zeros(6), np.zeros(6)  # the last CC fit (`true_state`)
        # recording (`record` / `finish`): per control step the rod nodes and the master state only; the
        # recorded geometry is computed from them once at the end
        self._pos_hist = np.zeros((scn.n_steps, 3, nn))
        self._m_hist = np.zeros((scn.n_steps, 4))
        self._dist = np.zeros(nn)
        self._objs, cdamp = rod_contact.contact_arrays(scn.environment, self.slave._b.mass)
        if scn.environment.objects:
            try:
                s0 = initial_state(scn)
            except InitialStateError:
                s0 = None  # reported by the loop as an impossible start
            if s0 is not None:
                self.slave.reset(s0[4:10])
                rod_contact.check_clearance(scn.environment, self._objs, self.slave._b.position_collection)
            self.slave.set_contacts(self._objs, cdamp)

    # --- SteppedPlant -------------------------------------------------------------------------------
    def reset(self, state0: np.ndarray) -> None:
        state0 = np.asarray(state0, dtype=float)
        self._m[:] = state0[0:4]
        self.slave.reset(state0[4:10], state0[10:16])
        self.slave.external_tip_force(self.F2)
        self._T1[:] = 0.0
        self._T2[:] = 0.0
        self._q_ref[:] = state0[4:10]
        self.muscle_force[:] = 0.0
        self._ctrl[:] = 0.0

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed=None) -> None:
        self._T1[:] = T1
        self._T2[:] = T2
        self._q_ref[:] = q2_ref
        if self.actuation == "muscle":
            self.saturated += muscle_commands(q2_sensed, self._T2, self.slave.muscle_radius, self._fmax[::2],
                                              self._ctrl)
            np.clip(self._ctrl, 0.0, self._fmax, out=self._ctrl)

    def advance(self, dt: float) -> int:
        nsub = max(1, math.ceil(dt / MASTER_MAX_H - 1e-9))
        if not master_rk4(self.mpk, self._m, self._T1, self.F1, dt / nsub, nsub):
            return 1
        if self.actuation == "servo":
            if min(self._q_ref[0], self._q_ref[1], self._q_ref[2]) <= 0.0:
                return 5
            ff = None
            if self.feedforward:
                ff = self._ff
                feedforward(self._T2, self._q2, self._spk, ff)
            ok = self.slave.step(self._q_ref, dt, ff)
        elif self.actuation == "muscle":
            ok = self.slave.step(self.muscle_force, dt)
            self.muscle_force += (self._ctrl - self.muscle_force) * -np.expm1(-dt / self._tau)
        else:
            ok = self.slave.step(self._T2, dt)
        return 0 if ok else 8

    def true_state(self, out: np.ndarray) -> int:
        """out (16,) <- [q1, dq1, q2, dq2]; 8 (diverged) if the rod's CC fit fails arithmetically."""
        out[0:4] = self._m
        try:
            self.slave.sense_into(self._q2, self._dq2)  # CC fit, shared with the servo feed-forward
        except ArithmeticError:
            return 8
        out[4:10] = self._q2
        out[10:16] = self._dq2
        return 0

    @property
    def stop(self):
        """The run's stop flag (an Event or None): once set, the rod raises `RodStopped` between batches."""
        return self.slave.stop

    @stop.setter
    def stop(self, flag) -> None:
        self.slave.stop = flag

    def forces(self, F: np.ndarray, contact: np.ndarray) -> None:
        """True interaction forces ON the robots F (4,) [F1x, F1z, F2x, F2z] N (F2 = constant + contact force
        on the tip node, last rod substep) and the contact summary (5,) (`rod_contact.summary`)."""
        fc = self.slave.f_contact
        F[0:2] = self.F1
        F[2] = self.F2[0] + fc[0, -1]
        F[3] = self.F2[1] + fc[2, -1]
        rod_contact.summary(fc, self.slave._b.position_collection, self._objs, self._dist, contact)

    def slave_tip(self) -> np.ndarray:
        return self.slave.tip()

    def geometry(self) -> dict[str, np.ndarray]:
        """The same arrays every call, updated in place (valid until the next advance)."""
        g = self._geo
        cl = np.add(self.slave._b.position_collection.T, SLAVE_BASE, out=g["centreline"])
        g["sections"][:] = cl[self.slave.section_nodes]
        master_points(self.mpk, self._m[None], MASTER_BASE, g["master"][None])
        return g

    def record(self, k: int) -> None:
        """Keep the rod nodes and master state of control step k (the buffers grow for a longer run)."""
        if k >= self._pos_hist.shape[0]:
            n = max(k + 1, 2 * self._pos_hist.shape[0])
            self._pos_hist, self._m_hist = (np.concatenate([a, np.zeros((n - len(a), *a.shape[1:]))])
                                            for a in (self._pos_hist, self._m_hist))
        self._pos_hist[k] = self.slave._b.position_collection
        self._m_hist[k] = self._m

    def finish(self, traj, done: int) -> None:
        """The recorded geometry of steps 0..done-1, the numbers `slave_tip` and `geometry` give per step:
        traj.x2_plant (done, 2) tip node [X, Z], traj.master_pos (done, 3, 3), traj.meta["geometry"]
        {"centreline": (done, 3 n + 1, 3), "sections": (done, 4, 3)} (world frame, m), and `meta`."""
        pos = self._pos_hist[:done]
        cl = np.empty((done, pos.shape[2], 3))
        np.add(pos.transpose(0, 2, 1), SLAVE_BASE, out=cl)
        traj.x2_plant = np.ascontiguousarray(pos[:, [0, 2], -1])
        traj.master_pos = np.empty((done, 3, 3))
        master_points(self.mpk, self._m_hist[:done], MASTER_BASE, traj.master_pos)
        traj.meta["geometry"] = {"centreline": cl, "sections": cl.take(self.slave.section_nodes, axis=1)}
        traj.meta.update(self.meta())

    # --- the plant's state coordinates (SteppedPlant.get_state / set_state) ----------------------------
    # The rod in its plane without the clamped base node 0 (held by the boundary condition): node X, Z
    # (n_nodes - 1 each), element angle about Y, node velocities X, Z, element angular rate about Y.
    @property
    def state_names(self) -> list[str]:
        """[q1, dq1] (4), then the rod's planar coordinates and their rates (`get_state`)."""
        nn, ne, npe = self.slave.n * 3 + 1, self.slave.n * 3, self.slave.n
        node = [f"node{j}" for j in range(1, nn)]
        pos = [f"{n}.X" for n in node] + [f"{n}.Z" for n in node] + [f"s{j // npe}_el{j % npe}.angle"
                                                                       for j in range(ne)]
        muscle = [f"s{j // 2}_muscle{j % 2}.force" for j in range(6)] if self.actuation == "muscle" else []
        return ["q1[0]", "q1[1]", "dq1[0]", "dq1[1]", *pos, *(f"{n} (rate)" for n in pos), *muscle]

    def get_state(self, keep: bool = False) -> np.ndarray:
        """[q1, dq1, node X, node Z, element angle, their rates (, muscle group forces (6,) N under muscle
        actuation)]; keep: also the directors, the clamped base node and the rod's clock."""
        b = self.slave._b
        D, P, V = b.director_collection, b.position_collection, b.velocity_collection
        if keep or not hasattr(self, "_kept"):
            self._kept = (D.copy(), np.arctan2(D[2, 0], D[0, 0]), P[:, 0].copy(), self.slave.time,
                          self.slave._steps)
        ang = np.arctan2(D[2, 0], D[0, 0])
        act = self.muscle_force if self.actuation == "muscle" else ()
        return np.concatenate([self._m, P[0, 1:], P[2, 1:], ang, V[0, 1:], V[2, 1:], b.omega_collection[1],
                               act])

    def set_state(self, x: np.ndarray) -> None:
        s = self.slave
        b, m, ne = s._b, s._b.position_collection.shape[1] - 1, s._b.director_collection.shape[2]
        dirs, a0, base, s.time, s._steps = self._kept
        self._m[:] = x[0:4]
        b.position_collection[:, 0] = base
        b.position_collection[0, 1:] = x[4:4 + m]
        b.position_collection[2, 1:] = x[4 + m:4 + 2 * m]
        i = 4 + 2 * m + ne
        b.velocity_collection[:, 0] = 0.0
        b.velocity_collection[0, 1:] = x[i:i + m]
        b.velocity_collection[2, 1:] = x[i + m:i + 2 * m]
        b.omega_collection[1] = x[i + 2 * m:i + 2 * m + ne]
        if self.actuation == "muscle":
            self.muscle_force[:] = x[i + 2 * m + ne:i + 2 * m + ne + 6]
        # the kept directors rotated about Y by the change of angle: row r of D (d1, d2, d3 in lab
        # coordinates) -> (r_x c + r_z s, r_y, -r_x s + r_z c)
        da = x[4 + 2 * m:i] - a0
        c, sn = np.cos(da), np.sin(da)
        D = b.director_collection
        D[:] = dirs
        D[:, 0] = dirs[:, 0] * c + dirs[:, 2] * sn
        D[:, 2] = -dirs[:, 0] * sn + dirs[:, 2] * c
        s._fit_valid = False

    def meta(self) -> dict:
        """Plant description for the recording and metrics.json."""
        s = self.slave
        return {"master_base": tuple(MASTER_BASE.tolist()), "slave_base": tuple(SLAVE_BASE.tolist()),
                "actuation": self.actuation, "elements_per_section": s.n, "rod_dt": s.dt,
                "stable_dt": self.stable_dt, "section_nodes": s.section_nodes.tolist(),
                **({"muscle_saturated_steps": self.saturated} if self.actuation == "muscle" else {})}
