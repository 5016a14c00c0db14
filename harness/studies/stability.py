"""Linear stability of the sampled-data closed loop at a point of a scenario (docs/stability.md): `linearize`
differentiates the one-period map x_{k+1} = Phi_k(x_k) (`ClosedLoopMap`).  Verdict: "unstable" if
rho = max |lambda| > 1 + T / SLOW_S, "marginal" if 1 < rho (a slow drift), else "stable"."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from controllers.params import Q2_NAMES
from controllers.status import Status
from harness.config.scenario import Scenario
from harness.loop.mj_warnings import warning_detail, warning_sink

SLOW_S = 1.0  # s: modes e-folding slower than this are "marginal" (slow drift), not "unstable"


class LinearizationError(RuntimeError):
    """The scenario cannot be linearized (unsupported controller, or the run failed before t)."""


def _positions(plant) -> tuple[np.ndarray, object]:
    """(indices of the position components of the plant state, x -> the slave's points [X, Z] (m, base
    first) at plant state x), for the mode shapes."""
    if plant.kind == "analytic":
        from controllers.slave import backbone

        return np.r_[0:2, 4:10], lambda x, slave: backbone(slave, x[4:10], 20)
    if plant.kind == "mujoco":
        import mujoco

        m = plant.m
        bodies = [b for b in range(m.nbody) if m.body(b).name.startswith("octarm_s")]
        base = plant.cmap.octarm_base_pos

        def points(x, slave):  # noqa: ARG001 - the chain's segment bodies at state x
            d = mujoco.MjData(m)
            d.qpos[:] = x[:m.nq]
            mujoco.mj_kinematics(m, d)
            return np.array([[d.xpos[b][0] - base[0], d.xpos[b][2] - base[2]] for b in bodies])

        return np.arange(m.nq), points
    n = plant.slave._b.position_collection.shape[1] - 1  # the rod's nodes without the clamped base node
    base = plant.slave._b.position_collection[[0, 2], 0].copy()
    npos = 2 * n + plant.slave._b.director_collection.shape[2]
    return np.r_[0:2, 4:4 + npos], lambda x, slave: np.vstack([base, np.stack([x[4:4 + n],
                                                                                x[4 + n:4 + 2 * n]], 1)])


class ClosedLoopMap:
    """The closed loop of `scn` (paper law, no sensing noise; the stepped loop's `Stepper`) over one control
    period.  Loop state x = [plant state (`get_state`: analytic [q1, dq1, q2, dq2]; mujoco qpos, qvel,
    act; cosserat [q1, dq1], node X, Z without the base, element angles about Y, their rates), servo
    reference (12, servo only), delay ring (delay x 26), filtered dq2 (6, with sensing.dq2_cutoff)].
    `warnings`: MuJoCo's warning text of the `linearize` in progress (captured as a run's, not printed)."""

    def __init__(self, scn: Scenario) -> None:
        if scn.controller.name != "paper":
            raise LinearizationError(f"controller.name: {scn.controller.name!r} cannot be linearized; only "
                                     "'paper' (the harness sees its whole state)")
        from harness.loop.common import compile_model, noise_table
        from harness.loop.stepped_loop import Stepper
        from harness.loop.stepped_plants import stepped_plant
        from harness.loop.trajectory import ROW_WIDTH
        from harness.plant import build_plant

        model = compile_model(scn)
        self.dt = scn.control_dt
        self.plant = stepped_plant(scn, model, build_plant(scn))
        self.plant.reset(model.s0)
        # noise off; the sensed-dq2 filter's columns of the table (gain, filtered dq2) when it is on
        table, _ = noise_table(dataclasses.replace(scn, snr_db=None), 1)
        self.stepper = Stepper(scn, self.plant, model, noise=(table, 0.0))
        self.filt = table[0, -6:] if scn.sensing.dq2_cutoff is not None else None  # a view: the filter state
        self.row = np.zeros(ROW_WIDTH)
        self.k = 0
        self.warnings: list[str] = []
        try:
            self.names = list(self.plant.state_names)
        except NotImplementedError as exc:
            raise LinearizationError(str(exc)) from None
        self.n_plant = len(self.names)
        st = self.stepper
        ring = range(st.delay + 1 if st.delay else 0)
        # the loop state after the plant's: views of the servo reference, delay ring and filtered dq2
        extra = ((st.ref, [f"{n}_ref" for n in Q2_NAMES] + [f"d{n}/dt_ref" for n in Q2_NAMES], st.servo),
                 (st.cmdbuf.reshape(-1), [f"ring[{s}][{j}]" for s in ring for j in range(26)], st.delay),
                 (self.filt, [f"d{n}/dt_filtered" for n in Q2_NAMES], self.filt is not None))
        self.extra = [a for a, _, on in extra if on]
        self.names += [n for _, names, on in extra if on for n in names]

    def x(self) -> np.ndarray:
        return np.concatenate([self.plant.get_state(), *self.extra])

    def set_x(self, x: np.ndarray) -> None:
        i = self.n_plant
        self.plant.set_state(x[:i])
        for a in self.extra:
            a[:] = x[i:i + a.size]
            i += a.size

    def step(self) -> int:
        """One control step k -> k + 1; a `controllers.status.Status` code (0 = ok)."""
        st = self.stepper.step(self.k, self.row)
        if not st:
            self.k += 1
        return st

    @property
    def warned(self) -> dict[str, int]:
        """MuJoCo's warning counters by name when a step stopped on a warning (else {})."""
        return getattr(self.plant, "warned", None) or {}

    def _why(self, st: int) -> str:
        """A failed step's cause: the status text, with MuJoCo's warnings as a run's message gives them."""
        text = Status(st).text if st in Status._value2member_map_ else f"status {st}"
        return text + warning_detail(self.warned, self.warnings)

    def run_to(self, n: int) -> None:
        st, why = 0, ""
        while self.k < n and not (st or why):
            try:
                st = self.step()
            except Exception as exc:  # a plant that raises instead of returning a status: one line
                why = f"{type(exc).__name__}: {exc}"
        if st or why:
            why = why or self._why(st)
            raise LinearizationError(f"the run stopped before the point of linearization: {why} at "
                                     f"t = {self.k * self.dt:.4f} s") from None

    def phi(self, x: np.ndarray, k: int) -> np.ndarray:
        """Phi_k(x): the loop state one control period after state x at step k."""
        self.set_x(x)
        self.k = k
        st = self.step()
        if st:
            raise LinearizationError(f"a perturbed step failed ({self._why(st)}); use a smaller step h")
        return self.x()


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
    positions_idx: np.ndarray  # indices of the plant state's position components
    shapes: dict  # {"positions": x, slave -> the slave's points (m, 2), "slave": SlaveParams}
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
                f"growth {self.growth_rate(0):+.3g} 1/s, on {dom}")

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
    if h is None:
        h = 1e-6 if scn.plant.kind == "analytic" else 1e-7
    with warning_sink() as lp.warnings:  # the run and every perturbed step (`harness.loop.mj_warnings`)
        lp.run_to(int(round(t / scn.control_dt)))
        lp.plant.get_state(keep=True)
        x0 = lp.x()
        k = lp.k
        N = len(x0)
        A = np.zeros((N, N))
        for i in range(N):
            hi = h * max(1.0, abs(x0[i]))
            xp, xm = x0.copy(), x0.copy()
            xp[i] += hi
            xm[i] -= hi
            A[:, i] = (lp.phi(xp, k) - lp.phi(xm, k)) / (2 * hi)
        lp.set_x(x0)
    lp.k = k
    ev, V = np.linalg.eig(A)
    order = np.lexsort((-ev.imag, -np.round(np.abs(ev), 12)))
    idx, points = _positions(lp.plant)
    return Stability(scenario=scn, t=k * scn.control_dt, T=scn.control_dt, A=A, eigenvalues=ev[order],
                     eigenvectors=V[:, order], names=lp.names, x0=x0, n_plant=lp.n_plant, h=h,
                     positions_idx=idx, shapes={"positions": points, "slave": scn.plant_slave})


__all__ = ["ClosedLoopMap", "LinearizationError", "SLOW_S", "Stability", "linearize"]
