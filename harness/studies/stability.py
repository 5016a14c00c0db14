"""Linear stability of the sampled-data closed loop around a point of a scenario (docs/stability.md).

The loop over one control period T is a map x_{k+1} = Phi_k(x_k), x = [plant state, servo reference
(servo actuation), actuation-delay ring]; `linearize(scn, t)` runs the scenario to t (paper law, noise
off) and differentiates the whole one-period map by central finite differences.  Plant coordinates:
analytic [q1, dq1, q2, dq2]; mujoco qpos, qvel, act (the rest of MuJoCo's state restored from the point
of linearization); cosserat the master [q1, dq1], then node X, Z (without the clamped base node), element
angles about Y and their rates.  Verdict: "unstable" if rho = max |lambda| > 1 + T / SLOW_S, "marginal"
if 1 < rho <= 1 + T / SLOW_S (a slow drift such as the null-space positions), else "stable".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controllers.control import MASTER_INFO, SLAVE_INFO
from controllers.status import Status
from harness.config.scenario import Scenario

SLOW_S = 1.0  # s: modes e-folding slower than this are "marginal" (slow drift), not "unstable"
EXPLODING = 1e6  # as harness.loop.stepped_loop
Q2_NAMES = ("d1", "d2", "d3", "k1", "k2", "k3")


class LinearizationError(RuntimeError):
    """The scenario cannot be linearized (unsupported controller, or the run failed before t)."""


# --- plant state get / set (what the loop should expose as plant.get_state() / set_state()) ---------------
class _AnalyticState:
    def __init__(self, plant) -> None:
        self.p = plant
        self.names = ["q1[0]", "q1[1]", "dq1[0]", "dq1[1]", *Q2_NAMES, *("d" + n + "/dt" for n in Q2_NAMES)]
        self.positions_idx = np.r_[0:2, 4:10]

    def anchor(self) -> None:
        """Nothing besides the state to keep."""

    def get(self) -> np.ndarray:
        return self.p.state.copy()

    def set(self, x: np.ndarray) -> None:
        self.p.state[:] = x

    def restore(self, x: np.ndarray) -> None:
        self.set(x)

    def positions(self, x: np.ndarray, slave) -> np.ndarray:
        """Slave backbone [X, Z] (m, base first) of state x."""
        from controllers.slave import backbone

        return backbone(slave, x[4:10], 20)


class _MujocoState:
    def __init__(self, plant) -> None:
        import mujoco

        self.mj = mujoco
        self.p = plant
        m = plant.m
        if m.nq != m.nv:
            raise LinearizationError("plant: the MuJoCo model has ball or free joints (nq != nv); "
                                     "only hinge and slide joints are supported")
        self.nq, self.nv, self.na = m.nq, m.nv, m.na
        self.spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.full = np.empty(mujoco.mj_stateSize(m, self.spec))
        jn = {int(m.jnt_qposadr[j]): mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
              for j in range(m.njnt)}
        qn = [jn.get(i, f"qpos[{i}]") for i in range(self.nq)]
        self.names = qn + [f"{n} (rate)" for n in qn] + [f"act[{i}]" for i in range(self.na)]
        self.positions_idx = np.arange(self.nq)
        self.bodies = [b for b in range(m.nbody)
                       if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or "").startswith("octarm_s")]

    def anchor(self) -> None:
        """Keep MuJoCo's whole physics state (time, warm start, ...) of the point of linearization."""
        self.mj.mj_getState(self.p.m, self.p.d, self.full, self.spec)

    def get(self) -> np.ndarray:
        d = self.p.d
        return np.concatenate([d.qpos, d.qvel, d.act])

    def set(self, x: np.ndarray) -> None:
        """Restore the physics state kept by `anchor`, then x."""
        d = self.p.d
        self.mj.mj_setState(self.p.m, d, self.full, self.spec)
        d.qpos[:] = x[:self.nq]
        d.qvel[:] = x[self.nq:self.nq + self.nv]
        d.act[:] = x[self.nq + self.nv:]
        self.mj.mj_forward(self.p.m, d)

    restore = set

    def positions(self, x: np.ndarray, slave) -> np.ndarray:  # noqa: ARG002
        """[X, Z] (m) of the chain's segment bodies (MuJoCo body order, base first) at state x."""
        m, d = self.p.m, self.mj.MjData(self.p.m)
        d.qpos[:] = x[:self.nq]
        self.mj.mj_kinematics(m, d)
        base = self.p.cmap.octarm_base_pos
        return np.array([[d.xpos[b][0] - base[0], d.xpos[b][2] - base[2]] for b in self.bodies])


class _CosseratState:
    """Planar rod coordinates without the clamped base node 0 (held by the rod's boundary condition: zero
    velocity, zero net force, so a perturbation of it would be a neutral mode of no physical meaning)."""

    def __init__(self, plant) -> None:
        self.p = plant
        b = plant.slave._b
        self.nn, self.ne = b.position_collection.shape[1], b.director_collection.shape[2]
        npe = plant.slave.n
        node = [f"node{j}" for j in range(1, self.nn)]
        elem = [f"s{j // npe}_el{j % npe}" for j in range(self.ne)]
        pos = [f"{n}.X" for n in node] + [f"{n}.Z" for n in node] + [f"{e}.angle" for e in elem]
        self.names = ["q1[0]", "q1[1]", "dq1[0]", "dq1[1]", *pos, *(f"{n} (rate)" for n in pos)]
        self.positions_idx = np.r_[0:2, 4:4 + len(pos)]

    def anchor(self) -> None:
        """Keep the directors, the clamped base node and the rod's clock of the point of linearization."""
        b = self.p.slave._b
        self._dirs = b.director_collection.copy()
        self._a0 = np.arctan2(self._dirs[2, 0], self._dirs[0, 0])
        self._base = b.position_collection[:, 0].copy()
        self._time, self._steps = self.p.slave.time, self.p.slave._steps

    def get(self) -> np.ndarray:
        b = self.p.slave._b
        D = b.director_collection
        P, V = b.position_collection, b.velocity_collection
        ang = np.arctan2(D[2, 0], D[0, 0])
        return np.concatenate([self.p._m, P[0, 1:], P[2, 1:], ang, V[0, 1:], V[2, 1:], b.omega_collection[1]])

    def set(self, x: np.ndarray) -> None:
        p, s = self.p, self.p.slave
        b, m, ne = s._b, self.nn - 1, self.ne
        p._m[:] = x[0:4]
        i = 4
        b.position_collection[:, 0] = self._base
        b.position_collection[0, 1:] = x[i:i + m]
        b.position_collection[2, 1:] = x[i + m:i + 2 * m]
        ang = x[i + 2 * m:i + 2 * m + ne]
        i += 2 * m + ne
        b.velocity_collection[:, 0] = 0.0
        b.velocity_collection[0, 1:] = x[i:i + m]
        b.velocity_collection[2, 1:] = x[i + m:i + 2 * m]
        b.omega_collection[1] = x[i + 2 * m:i + 2 * m + ne]
        # rotate the stored directors about Y by the change of angle; D has rows d1, d2, d3 in lab
        # coordinates and row r -> (r_x c + r_z s, r_y, -r_x s + r_z c) takes _rot_y(a) to _rot_y(a + da)
        # (harness.plant.cosserat)
        da = ang - self._a0
        c, sn = np.cos(da), np.sin(da)
        D = self._dirs
        out = D.copy()
        for r in range(3):
            out[r, 0] = D[r, 0] * c + D[r, 2] * sn
            out[r, 2] = -D[r, 0] * sn + D[r, 2] * c
        b.director_collection[:] = out
        s._fit_valid = False
        s.time, s._steps = self._time, self._steps

    restore = set

    def positions(self, x: np.ndarray, slave) -> np.ndarray:  # noqa: ARG002
        """Rod nodes [X, Z] (m), base first."""
        m = self.nn - 1
        pts = np.stack([x[4:4 + m], x[4 + m:4 + 2 * m]], axis=1)
        return np.vstack([[self._base[0], self._base[2]], pts])


# --- the one-period closed-loop map -----------------------------------------------------------------------
class ClosedLoopMap:
    """The closed loop of `scn` (paper law, no sensing noise) as a map over one control period.

    `run_to(n)` steps it from t = 0 to step n; `x()` / `set_x(x)` read / write the loop state
    [plant state, servo reference [q2_ref, dq2_ref] (12, servo only), delay ring (delay x 26)];
    `phi(x, k)` is the state one control period after state x at step k (the loop is left there; `set_x`
    goes back)."""

    def __init__(self, scn: Scenario) -> None:
        if scn.controller.name != "paper":
            raise LinearizationError(f"controller.name: {scn.controller.name!r} cannot be linearized; only "
                                     "'paper' (the harness sees its whole state)")
        from harness.loop.common import compile_model
        from harness.loop.fast import K
        from harness.loop.stepped_plants import stepped_plant
        from harness.plant import build_plant

        self.scn, self.K = scn, K
        self.model = compile_model(scn)
        self.plant = stepped_plant(scn, self.model, build_plant(scn))
        self.plant.reset(self.model.s0)
        kind = scn.plant.kind
        states = {"analytic": _AnalyticState, "mujoco": _MujocoState, "cosserat": _CosseratState}
        self.ps = states[kind](self.plant)
        self.dt = scn.control_dt
        self.servo = self.plant.actuation == "servo"
        self.delay = int(round(scn.plant.actuation_delay / self.dt))
        self.slots = self.delay + 1
        s0 = self.model.s0
        self.ref = np.concatenate([s0[4:10], s0[10:16]])
        self.cmdbuf = np.zeros((self.slots, 26))
        self.cmdbuf[:, 8:20] = self.ref
        self.views = [(c[0:2], c[2:8], c[8:14], c[14:20], c[20:26]) for c in self.cmdbuf]
        self.state, self.sensed = np.zeros(16), np.zeros(16)
        self.Ftrue, self.cinfo = self.model.F.copy(), np.zeros(5)
        self.Fsens = self.model.F.copy()
        self.ignored = scn.sensing.force.mode == "ignored"
        self.noise = np.zeros((1, 16))
        self.bufs = [np.zeros(2) for _ in range(3)] + [np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6)]
        self.minfo, self.sinfo = np.empty(MASTER_INFO), np.empty(SLAVE_INFO)
        self.row = np.zeros(_row_width())
        from harness.loop.trajectory import ROW_SLICES

        self.iF, self.iFs, self.iC = (ROW_SLICES[n].start for n in ("F_true", "F_sensed", "contact"))
        self.forces = getattr(self.plant, "forces", None)
        self.k = 0
        self.names = list(self.ps.names)
        if self.servo:
            self.names += [f"{n}_ref" for n in Q2_NAMES] + [f"d{n}/dt_ref" for n in Q2_NAMES]
        self.names += [f"ring[{s}][{j}]" for s in range(self.slots if self.delay else 0) for j in range(26)]
        self.n_plant = len(self.ps.names)

    # loop state
    def x(self) -> np.ndarray:
        parts = [self.ps.get()]
        if self.servo:
            parts.append(self.ref.copy())
        if self.delay:
            parts.append(self.cmdbuf.ravel().copy())
        return np.concatenate(parts)

    def set_x(self, x: np.ndarray) -> None:
        i = self.n_plant
        self.ps.set(x[:i])
        if self.servo:
            self.ref[:] = x[i:i + 12]
            i += 12
        if self.delay:
            self.cmdbuf.ravel()[:] = x[i:]

    def step(self) -> int:
        """One control step k -> k + 1 (the per-step body of `harness.loop.stepped_loop`, noise-free).
        Returns a `controllers.status.Status` code (0 = ok)."""
        K, a, k, dt = self.K, self.model, self.k, self.dt
        st = self.plant.true_state(self.state)
        if st:
            return int(st)
        if self.forces is not None:
            self.forces(self.Ftrue, self.cinfo)
        xd, dxd, ddxd, T1, T2, u2, deN = self.bufs
        s0, st = K.stepped_paper_step(
            self.state, EXPLODING, self.Ftrue, self.ignored, k * dt, a.traj, self.noise, k, 0.0, a.mpk_c,
            a.spk_c, a.nodes, a.weights, a.gains, a.spec, self.Fsens, xd, dxd, ddxd, self.sensed, T1, T2, u2,
            deN, self.minfo, self.sinfo, self.row, self.cinfo, self.iF, self.iFs, self.iC,
            1 if self.servo else 0, self.ref, dt, self.cmdbuf[k % self.slots])
        if s0 or st:
            return int(s0 or st)
        self.plant.command(*self.views[(k - self.delay) % self.slots if k >= self.delay else 0])
        st = self.plant.advance(dt)
        self.k += 1
        return int(st or 0)

    def run_to(self, n: int) -> None:
        while self.k < n:
            try:
                st = self.step()
            except Exception as exc:  # a plant that raises instead of returning a status: one line
                t = self.k * self.dt
                raise LinearizationError(f"the run stopped before the point of linearization: "
                                         f"{type(exc).__name__}: {exc} at t = {t:.4f} s") from None
            if st:
                t = self.k * self.dt
                text = Status(st).text if st in Status._value2member_map_ else f"status {st}"
                raise LinearizationError(f"the run stopped before the point of linearization: {text} at "
                                         f"t = {t:.4f} s")

    def phi(self, x: np.ndarray, k: int) -> np.ndarray:
        """Phi_k(x): the loop state one control period after state x at step k."""
        self.set_x(x)
        self.k = k
        st = self.step()
        if st:
            raise LinearizationError(f"a perturbed step failed (status {st}); use a smaller step h")
        return self.x()


def _row_width() -> int:
    from harness.loop.trajectory import ROW_WIDTH

    return ROW_WIDTH


# --- linearization and modes ---------------------------------------------------------------------------
@dataclass
class Stability:
    """Result of `linearize`: A (n, n) the one-period Jacobian at t (s), its eigenvalues (n,) sorted by
    decreasing modulus and eigenvectors (n, n) (columns), the state names (n,), T (s) and what was run."""

    scenario: Scenario
    t: float
    T: float
    A: np.ndarray
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    names: list[str]
    x0: np.ndarray
    n_plant: int
    h: float
    positions_idx: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    shapes: dict = field(default_factory=dict)
    stopped: str = ""  # linearized along a run (`least_stable_along`): why the run ended early, if it did

    @property
    def radius(self) -> float:
        return float(abs(self.eigenvalues[0]))

    def frequency(self, j: int = 0) -> float:
        """Hz, angle(lambda_j) / (2 pi T) (0 for a real positive mode, 1 / (2 T) for a flip)."""
        return float(abs(np.angle(self.eigenvalues[j])) / (2 * math.pi * self.T))

    def growth_rate(self, j: int = 0) -> float:
        """1/s, ln |lambda_j| / T (> 0 grows)."""
        return float(math.log(max(abs(self.eigenvalues[j]), 1e-300)) / self.T)

    def most_negative(self) -> int:
        """Index of the eigenvalue with the most negative real part (a flip mode when it is real: a sign
        change every period; it leaves the unit circle at -1)."""
        return int(np.argmin(self.eigenvalues.real))

    @property
    def verdict_class(self) -> str:
        r = self.radius
        if r > 1.0 + self.T / SLOW_S:
            return "unstable"
        return "marginal" if r > 1.0 else "stable"

    def dominant(self, j: int = 0, n: int = 4) -> list[tuple[str, float]]:
        """The n plant-state components of mode j with the largest share of its position part (the whole
        plant state if the mode has no position part), as (name, share of the largest) pairs."""
        v = np.abs(self.eigenvectors[: self.n_plant, j])
        idx = self.positions_idx if v[self.positions_idx].max() > 1e-9 * v.max() else np.arange(len(v))
        part = v[idx]
        order = np.argsort(-part)[:n]
        return [(self.names[int(idx[i])], float(part[i] / part[order[0]])) for i in order]

    def verdict(self) -> str:
        lam = self.eigenvalues[0]
        dom = ", ".join(nm for nm, _ in self.dominant(0))
        c = self.verdict_class
        return (f"{c}: spectral radius {self.radius:.6f} at t = {self.t:g} s (T = {self.T:g} s), "
                f"least stable mode lambda = {lam.real:+.6f}{lam.imag:+.6f}j, {self.frequency(0):.2f} Hz, "
                f"growth "
                f"{self.growth_rate(0):+.3g} 1/s, on {dom}")

    def spectrum_rows(self) -> list[dict]:
        return [{"index": j, "real": float(e.real), "imag": float(e.imag), "modulus": float(abs(e)),
                 "angle": float(np.angle(e)), "frequency_hz": self.frequency(j),
                 "growth_per_s": self.growth_rate(j), "dominant": ";".join(n for n, _ in self.dominant(j))}
                for j, e in enumerate(self.eigenvalues)]


def linearize(scn: Scenario, t: float, h: float | None = None,
              loop: ClosedLoopMap | None = None) -> Stability:
    """Run `scn` (paper law, sensing noise off) to time t (s, rounded to a control step) and return the
    one-period Jacobian by central finite differences with step h (default 1e-6 on the analytic plant,
    1e-7 on MuJoCo and the rod; relative to max(1, |x_i|)), its eigen-decomposition and mode shapes.
    Raises LinearizationError if the run stops before t."""
    lp = loop if loop is not None else ClosedLoopMap(scn)
    n = int(round(t / scn.control_dt))
    lp.run_to(n)
    if h is None:
        h = 1e-6 if scn.plant.kind == "analytic" else 1e-7
    lp.ps.anchor()
    x0 = lp.x()
    k = lp.k
    N = len(x0)
    A = np.zeros((N, N))
    for i in range(N):
        hi = h * max(1.0, abs(x0[i]))
        xp = x0.copy()
        xp[i] += hi
        fp = lp.phi(xp, k)
        xm = x0.copy()
        xm[i] -= hi
        fm = lp.phi(xm, k)
        A[:, i] = (fp - fm) / (2 * hi)
    lp.set_x(x0)
    lp.k = k
    ev, V = np.linalg.eig(A)
    order = np.lexsort((-ev.imag, -np.round(np.abs(ev), 12)))
    res = Stability(scenario=scn, t=k * scn.control_dt, T=scn.control_dt, A=A, eigenvalues=ev[order],
                    eigenvectors=V[:, order], names=lp.names, x0=x0, n_plant=lp.n_plant, h=h)
    res.positions_idx = lp.ps.positions_idx
    res.shapes = {"positions": lp.ps.positions, "slave": scn.plant_slave}
    return res


__all__ = ["ClosedLoopMap", "LinearizationError", "SLOW_S", "Stability", "linearize"]
