"""Derived measurements of the findings: f(scenario, trajectory or None if `simulate = false`) -> {key:
value}, by name in MEASURES (a finding file's `measure = [...]`), units in MEASURE_UNITS."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np


def _measure_diverged(scn, traj) -> dict[str, float]:
    """diverged: 1 if the run diverged, else 0; diverged_at: the time it stopped (s)."""
    div = traj.status == "diverged"
    return {"diverged": float(div), "diverged_at": float(traj.t[-1]) if len(traj) else 0.0}


def _measure_eq28(scn, traj) -> dict[str, float]:
    """(28) from the recorded de_N: its central differences over the first 30 steps against the corrected
    -k_n P de_N - J2^+ dJ2 de_N and the printed +k_n P de_N - J2^+ dJ2 de_N, each as the largest residual
    relative to |k_n P de_N| (model terms at the recorded q2, dq2)."""
    from controllers import slave as slave_model

    kn = scn.gains.kn
    h = float(traj.t[1] - traj.t[0])
    fixed, printed = [], []
    for k in range(1, 31):
        q, dq, den = traj.q2[k], traj.dq2[k], traj.deN[k]
        J = slave_model.jacobian(scn.slave, q)
        Jd = slave_model.jacobian_dot(scn.slave, q, dq)
        Jp = J.T @ np.linalg.inv(J @ J.T)
        P = np.eye(6) - Jp @ J
        dde = (traj.deN[k + 1] - traj.deN[k - 1]) / (2 * h)
        scale = float(np.linalg.norm(kn * P @ den))
        fixed.append(float(np.linalg.norm(dde - (-kn * P @ den - Jp @ Jd @ den))) / scale)
        printed.append(float(np.linalg.norm(dde - (kn * P @ den - Jp @ Jd @ den))) / scale)
    return {"eq28_corrected": max(fixed), "eq28_printed": min(printed),
            "central_difference_error": (h * kn) ** 2 / 6}


def _second_order(t, e0, de0, a, b):
    """Closed-form solution of e'' + a e' + b e = 0 (each column of e0, de0), any damping."""
    disc = a * a - 4 * b
    t = t[:, None]
    if disc < 0:
        s, w = -a / 2, np.sqrt(-disc) / 2
        return np.exp(s * t) * (e0 * np.cos(w * t) + (de0 - s * e0) / w * np.sin(w * t))
    r1, r2 = (-a + np.sqrt(disc)) / 2, (-a - np.sqrt(disc)) / 2
    c2 = (de0 - r1 * e0) / (r2 - r1)
    return (e0 - c2) * np.exp(r1 * t) + c2 * np.exp(r2 * t)


def _measure_closed_forms(scn, traj) -> dict[str, float]:
    """The recorded e1 and e2 against the closed-form solutions of (15) (k1, k2) and (21) (k3, k4) from
    their recorded initial values: the largest deviation relative to the largest initial component."""
    g = scn.gains
    cases = (("eq15_error", traj.e1, traj.de1, g.k1, g.k2), ("eq21_error", traj.e2, traj.de2, g.k3, g.k4))
    return {key: float(np.abs(e - _second_order(traj.t, e[0], de[0], a, b)).max() / np.abs(e[0]).max())
            for key, e, de, a, b in cases}


def _measure_beta(scn, traj) -> dict[str, float]:
    """beta_final, beta_mean: the manipulability (41) at the end of the run and averaged over it."""
    return {"beta_final": float(traj.beta[-1]), "beta_mean": float(np.mean(traj.beta))}


def _measure_straight(scn, traj) -> dict[str, float]:
    """beta (41) of the straight arm at rest lengths, from the controllers' model and from the closed
    form sqrt(3 sum a_i^2), a_i = d_i^2 / 2 + d_i sum_{j>i} d_j (lengths move Z, curvatures move X)."""
    from controllers.subtasks import manipulability

    d = np.asarray(scn.slave.rest_lengths, float)
    beta = float(manipulability(scn.slave, np.concatenate([d, np.zeros(3)])))
    a = d**2 / 2 + d * (d.sum() - np.cumsum(d))
    closed = float(np.sqrt(3 * np.sum(a**2)))
    return {"beta_straight": beta, "beta_straight_closed_form": closed,
            "beta_straight_difference": abs(beta - closed)}


ROD_SETTLED_SPEED = 1e-6  # m/s: the rod is at equilibrium when no node moves faster than this
ROD_SETTLE_CHECK = 0.25  # s between checks of the node speeds
ROD_SETTLE_MAX = 30.0  # s: give up (the measure is then nan)


def _arc_departure(p: np.ndarray) -> float:
    """Largest distance (m) of the points p (n, 2) from their least-squares circle (algebraic fit);
    for a nearly straight section (radius above 1e3 m) the distance from the least-squares line."""
    A = np.c_[2 * p, np.ones(len(p))]
    c = np.linalg.lstsq(A, (p**2).sum(1), rcond=None)[0]
    centre = c[:2]
    R2 = c[2] + centre @ centre
    if R2 > 0 and np.sqrt(R2) < 1e3:
        return float(np.abs(np.linalg.norm(p - centre, axis=1) - np.sqrt(R2)).max())
    q = p - p.mean(0)
    normal = np.linalg.svd(q)[2][-1]
    return float(np.abs(q @ normal).max())


def _settled_rod(scn, law: str):
    """The rod (elastic law `law`) servoed to the "alternating max" shape, settled under gravity (eta_b
    0.3 N m^2 s, eta_a 3 N s) to ROD_SETTLED_SPEED: returns (rod, settle time s, tip at 3 s, converged)."""
    from harness.plant.cosserat import CosseratSlave
    from harness.studies.fidelity_reference import static_shapes

    slave = scn.plant.slave if scn.plant.slave is not None else scn.slave
    q2c = static_shapes(slave)["alternating max"]
    rod = CosseratSlave(slave, actuation="servo", elastic_law=law, material_damping=(0.3, 3.0))
    rod.reset(q2c)
    rod.external_tip_force((0.0, 0.0))
    chunk = round(ROD_SETTLE_CHECK / rod.dt) * rod.dt
    t, tip_3s, speed = 0.0, None, np.inf
    before = rod.centreline()
    while t < ROD_SETTLE_MAX and (speed > ROD_SETTLED_SPEED or tip_3s is None):
        rod.step(q2c, chunk)
        t += chunk
        now = rod.centreline()
        speed = float(np.linalg.norm(now - before, axis=1).max() / chunk)  # mean node speed over the chunk
        before = now
        if tip_3s is None and t >= 3.0 - 1e-9:
            tip_3s = rod.tip()
    return rod, t, tip_3s, speed <= ROD_SETTLED_SPEED


def _measure_rod_statics(scn, traj) -> dict[str, float]:
    """`_settled_rod` (`linear` law), in mm: arc_departure (largest node distance from its section's
    best-fit circle), chained_cc_tip (tip to the tip of the chained CC fits), settle_3s_error (tip after
    3 s to equilibrium); settle_time (s)."""
    from controllers import slave as slave_model

    rod, t, tip_3s, converged = _settled_rod(scn, "linear")
    if not converged:
        return {"arc_departure": math.nan, "chained_cc_tip": math.nan, "settle_3s_error": math.nan,
                "settle_time": t}
    nodes = rod.centreline()[:, [0, 2]]
    sn = rod.section_nodes
    arc = max(_arc_departure(nodes[sn[i]:sn[i + 1] + 1]) for i in range(3))
    slave = scn.plant.slave if scn.plant.slave is not None else scn.slave
    chained = float(np.linalg.norm(rod.tip() - slave_model.tip_position(slave, rod.sense()[0])))
    return {"arc_departure": 1e3 * arc, "chained_cc_tip": 1e3 * chained,
            "settle_3s_error": 1e3 * float(np.linalg.norm(rod.tip() - tip_3s)), "settle_time": t}


def _measure_elastic_laws(scn, traj) -> dict[str, float]:
    """law_gap (mm): the distance between the tips of the rod of `_settled_rod` with the `linear` and
    with the `analytic` elastic law (nan if either did not settle)."""
    a, _, _, ok_a = _settled_rod(scn, "linear")
    b, _, _, ok_b = _settled_rod(scn, "analytic")
    gap = 1e3 * float(np.linalg.norm(a.tip() - b.tip())) if ok_a and ok_b else math.nan
    return {"law_gap": gap}


def _settled_chain(scn, enforce_cc: bool):
    """The passive MuJoCo chain (`fidelity_reference.PassiveChain`, `linear` law) at the shape of
    `_settled_rod`, settled like it.  Returns (chain, converged)."""
    from harness.studies.fidelity_reference import SETTLE_DAMPING, PassiveChain, static_shapes

    slave = scn.plant.slave if scn.plant.slave is not None else scn.slave
    ch = PassiveChain(slave, scn.plant.segments, enforce_cc, 0.01, 0.3)
    ch.reset(static_shapes(slave)["alternating max"])
    ch.force((0.0, 0.0))
    t, speed = 0.0, np.inf
    before = ch.d.xpos.copy()
    while t < ROD_SETTLE_MAX and speed > ROD_SETTLED_SPEED and ch.ok():
        ch.run(ROD_SETTLE_CHECK, SETTLE_DAMPING)
        t += ROD_SETTLE_CHECK
        speed = float(np.linalg.norm(ch.d.xpos - before, axis=1).max() / ROD_SETTLE_CHECK)
        before = ch.d.xpos.copy()
    return ch, speed <= ROD_SETTLED_SPEED


def _measure_chain_vs_rod(scn, traj) -> dict[str, float]:
    """Tip distances (mm) at equilibrium of `_settled_rod` (`linear` law) to `_settled_chain` without
    (free_chain_error) and with the CC constraints (cc_chain_error); nan for a body that did not settle."""
    rod, _, _, ok = _settled_rod(scn, "linear")
    out = {}
    for key, cc in (("free_chain_error", False), ("cc_chain_error", True)):
        ch, settled = _settled_chain(scn, cc)
        out[key] = 1e3 * float(np.linalg.norm(ch.tip() - rod.tip())) if ok and settled else math.nan
    return out


def _measure_flip(scn, traj) -> dict[str, float]:
    """The loop linearized at the run's end (`harness.studies.stability`): radius (spectral), flip = -Re
    of the most negative eigenvalue (> 1: a growing sign flip every period), flip_on_junction = 1 if
    that mode's two largest components are hinges (chain) or elements (rod) at a section boundary."""
    from harness.studies.stability import linearize

    res = linearize(scn, float(traj.t[-1]) if len(traj) else 0.0)
    j = res.most_negative()
    top = [name for name, _ in res.dominant(j, 2)]
    rod = scn.plant.kind == "cosserat"
    n = scn.plant.cosserat.elements_per_section if rod else scn.plant.segments
    pattern = "s{}_el{}.angle" if rod else "octarm_s{}_seg{}_hinge"
    junction = {pattern.format(i, n - 1) for i in range(2)} | {pattern.format(i, 0) for i in (1, 2)}
    return {"radius": res.radius, "flip": float(-res.eigenvalues[j].real),
            "flip_on_junction": float(all(any(name.startswith(x) for x in junction) for name in top))}


def _measure_poles(scn, traj) -> dict[str, float]:
    """The loop linearized at the run's end against the closed forms: pole_error = the largest distance
    (|.|) of a pole of (15) (k1, k2) or (21) (k3, k4) under a zero-order hold over T, each twice (X, Z),
    the one-period matrix [[1 - kp T^2/2, T - kd T^2/2], [-kp T, 1 - kd T]], to its nearest eigenvalue
    not matched before; null_error: the same for 1 - k_n T (the null-space velocity, 4 times)."""
    from harness.studies.stability import linearize

    g, T = scn.gains, scn.control_dt
    lam = list(linearize(scn, float(traj.t[-1])).eigenvalues)

    def worst(targets) -> float:
        err = 0.0
        for z in targets:
            j = int(np.argmin([abs(x - z) for x in lam]))
            err = max(err, abs(lam.pop(j) - z))
        return err

    zoh = [np.linalg.eigvals([[1 - kp * T * T / 2, T - kd * T * T / 2], [-kp * T, 1 - kd * T]])
           for kp, kd in ((g.k2, g.k1), (g.k4, g.k3))]
    poles = [z for pair in zoh for z in pair] * 2
    return {"pole_error": worst(poles), "null_error": worst([1 - g.kn * T] * 4)}


MARGIN_BOUNDS = {"analytic": "paper_analytic", "mujoco": "paper_mujoco", "cosserat": "paper_cosserat"}


def _measure_margins(scn, traj) -> dict[str, float]:
    """`margin.margins` against the plant's paper bounds over slave_mass and master_mass (no probes, one
    thread): <p>_lower, <p>_upper, <p>_lower_fail, <p>_upper_fail (nan at a range end), scale factors."""
    import tempfile
    from pathlib import Path

    from harness.config.bounds import load_bounds
    from harness.config.load import dump_scenario
    from harness.studies.margin import margins

    with tempfile.TemporaryDirectory() as tmp:
        src = dump_scenario(scn, Path(tmp) / "scenario.toml")
        rows = margins(scn, load_bounds(MARGIN_BOUNDS[scn.plant.kind]), ("slave_mass", "master_mass"),
                       source=src, probes=0, workers=1, executor="threads")
    sides = [(f"{m.param}_{side}", m.sides[side]) for m in rows for side in ("lower", "upper")]
    out = {k: d["margin"] for k, d in sides}
    return out | {f"{k}_fail": math.nan if d.get("fail") is None else d["fail"] for k, d in sides}


MEASURES: dict[str, Callable[[Any, Any], dict[str, float]]] = {
    "diverged": _measure_diverged,
    "closed_forms": _measure_closed_forms,
    "beta": _measure_beta,
    "eq28": _measure_eq28,
    "straight_manipulability": _measure_straight,
    "rod_statics": _measure_rod_statics,
    "elastic_laws": _measure_elastic_laws,
    "chain_vs_rod": _measure_chain_vs_rod,
    "flip": _measure_flip,
    "poles": _measure_poles,
    "margins": _measure_margins,
}

MEASURE_UNITS = {"diverged_at": "s", "arc_departure": "mm", "chained_cc_tip": "mm", "settle_3s_error": "mm",
                 "settle_time": "s", "law_gap": "mm", "free_chain_error": "mm", "cc_chain_error": "mm"}
