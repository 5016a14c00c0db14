"""Findings: the harness's scientific results as small runnable files, rerun by `teleop findings`.

A finding is one TOML file in the shipped `findings/` folder (package data `harness._data.findings`)::

    [finding]
    title = "Mass mismatch is first order"        # one line
    claim = "..."                                  # the sentence the checks below state
    method = "..."                                 # plant, settings, what is measured (optional)
    scenario = "paper"                             # base scenario (optional; default: the paper's)
    set = ["plant.kind='analytic'", ...]           # overrides applied to every run
    show = ["nominal.e2_rms"]                      # quantities reported beside the checks (optional)
    figures = ["nominal"]                          # runs whose Figs 2-4 `teleop findings` writes (optional)

    [[run]]                                        # one or more runs of the base scenario
    name = "plus10"
    set = ["plant.slave.masses=[1.1,0.77,0.44]"]   # this run's own overrides
    measure = ["diverged"]                         # optional derived measurements (MEASURES below)
    # simulate = false                             # only the measures (on the scenario), no closed loop

    [ratio]                                        # optional: quotient of two measured quantities
    plus20_over_plus10 = ["plus20.e2_rms", "plus10.e2_rms"]

    [claim]                                        # the claim as bounds: <quantity>_max / <quantity>_min
    plus20_over_plus10_min = 1.8
    plus20_over_plus10_max = 2.2
    [claim.plus10]                                 # a run's metrics: the bounds-file format
    status_ok = true                               #   (harness.config.bounds), checked by check_bounds
    e2_rms_min = 0.03

Quantities are named `<run>.<metric>` (every metric of `harness.loop.metrics.compute_metrics`),
`<run>.<measure key>` (the derived measurements) and `<ratio name>`.  Top-level `[claim]` keys bound
derived quantities and ratios (a dotted quantity is written with `_` for `.`, e.g. `exact_eq28_corrected`
for `exact.eq28_corrected`); `[claim.<run>]` tables are bounds files' `[bounds]` tables for that run.

`run_findings(names)` runs them and returns one `FindingResult` each; `findings_table` renders the
markdown table that the docs' findings page includes (claim, measured values, holds).  Everything is
deterministic: the same files give the same numbers.
"""

from __future__ import annotations

import difflib
import importlib.util
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.config.bounds import Bounds, Violation, bounds_from_dict, check_bounds
from harness.config.errors import ConfigError
from harness.config.textio import read_toml

_CHECKOUT = Path(__file__).resolve().parents[2]


def findings_dir() -> Path:
    """Folder of the shipped finding files (package data, else the checkout's `findings/`)."""
    try:
        spec = importlib.util.find_spec("harness._data.findings")
    except ModuleNotFoundError:
        spec = None
    for loc in (spec.submodule_search_locations or []) if spec is not None else []:
        if Path(loc).is_dir():
            return Path(loc)
    return _CHECKOUT / "findings"


# --------------------------------------------------------------------------------------------------
# derived measurements: f(scenario, trajectory) -> {key: float}


def _measure_diverged(scn, traj) -> dict[str, float]:
    """diverged: 1 if the run diverged, else 0; diverged_at: the time it stopped (s)."""
    div = traj.status == "diverged"
    return {"diverged": float(div), "diverged_at": float(traj.t[-1]) if len(traj) else 0.0}


def _measure_eq28(scn, traj) -> dict[str, float]:
    """The null-space error's dynamics (28) from the recorded de_N: central differences of de_N over
    the first 30 control steps against the corrected right-hand side -k_n P de_N - J2^+ dJ2 de_N and
    the printed +k_n P de_N - J2^+ dJ2 de_N, each as the largest residual relative to |k_n P de_N|
    (P, J2^+, dJ2 from the analytic model at the recorded q2, dq2)."""
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
    out = {}
    for key, e, de, a, b in (("eq15_error", traj.e1, traj.de1, g.k1, g.k2),
                             ("eq21_error", traj.e2, traj.de2, g.k3, g.k4)):
        ref = _second_order(traj.t, e[0], de[0], a, b)
        out[key] = float(np.abs(e - ref).max() / np.abs(e[0]).max())
    return out


def _measure_beta(scn, traj) -> dict[str, float]:
    """beta_final, beta_mean: the manipulability (41) at the end of the run and averaged over it."""
    return {"beta_final": float(traj.beta[-1]), "beta_mean": float(np.mean(traj.beta))}


def _measure_straight(scn, traj) -> dict[str, float]:
    """beta (41) of the straight arm at rest lengths, from the controllers' model and from the closed
    form sqrt(3 sum a_i^2), a_i = d_i^2 / 2 + d_i sum_{j>i} d_j (lengths move Z, curvatures move X)."""
    from controllers.subtasks import manipulability

    d = np.asarray(scn.slave.rest_lengths, float)
    q = np.concatenate([d, np.zeros(3)])
    beta = float(manipulability(scn.slave, q))
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
    """The Cosserat rod (the plant's slave parameters, elastic law `law`, 10 elements per section,
    servo rest strains at the fidelity study's worst shape: every section at full extension with
    alternating +-max bends) settled under gravity with the fidelity study's raised damping (eta_b
    0.3 N m^2 s, eta_a 3 N s) until no node moves faster than ROD_SETTLED_SPEED on average over a
    ROD_SETTLE_CHECK interval.  Returns (rod, settle time s, tip after 3 s, converged)."""
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
    """The rod of `_settled_rod` with the `linear` law (the fidelity study's).  In mm: arc_departure
    (the largest distance of a section's nodes from that section's best-fit circle), chained_cc_tip
    (the distance between the rod's tip and the tip of its per-section CC fits chained from the base),
    settle_3s_error (how far the tip still is from equilibrium after a fixed 3 s); settle_time (s)."""
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
    """The MuJoCo chain (the plant's segments and slave parameters) as a passive rod with the `linear`
    law at the shape of `_settled_rod` (`fidelity_reference.PassiveChain`, material damping 0.01 N m^2 s
    / 0.3 N s raised 30x while settling), stepped until no body moves faster than ROD_SETTLED_SPEED on
    average over a ROD_SETTLE_CHECK interval.  Returns (chain, converged)."""
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
    """Tip distances (mm) at equilibrium between the rod of `_settled_rod` (`linear` law) and the chains
    of `_settled_chain`: free_chain_error (no CC constraints) and cc_chain_error (CC enforced); nan for
    a body that did not settle."""
    rod, _, _, ok = _settled_rod(scn, "linear")
    out = {}
    for key, cc in (("free_chain_error", False), ("cc_chain_error", True)):
        ch, settled = _settled_chain(scn, cc)
        out[key] = 1e3 * float(np.linalg.norm(ch.tip() - rod.tip())) if ok and settled else math.nan
    return out


MEASURES: dict[str, Callable[[Any, Any], dict[str, float]]] = {
    "diverged": _measure_diverged,
    "closed_forms": _measure_closed_forms,
    "beta": _measure_beta,
    "eq28": _measure_eq28,
    "straight_manipulability": _measure_straight,
    "rod_statics": _measure_rod_statics,
    "elastic_laws": _measure_elastic_laws,
    "chain_vs_rod": _measure_chain_vs_rod,
}

# --------------------------------------------------------------------------------------------------
# the file format


@dataclass(frozen=True)
class RunSpec:
    name: str
    set: tuple[str, ...] = ()
    measure: tuple[str, ...] = ()
    bounds: Bounds | None = None  # [claim.<name>], the bounds-file format
    simulate: bool = True  # False: only the measures run (on the scenario), no closed loop


@dataclass(frozen=True)
class Finding:
    name: str
    title: str
    claim: str
    method: str
    scenario: str | None
    set: tuple[str, ...]
    runs: tuple[RunSpec, ...]
    ratios: dict[str, tuple[str, str]]
    limits: dict[str, tuple[str, str, float]]  # claim key -> (quantity key, "max" | "min", limit)
    show: tuple[str, ...] = ()  # further quantities reported beside the checks
    figures: tuple[str, ...] = ()  # runs whose Figs 2-4 are written (`write_outputs`)
    path: Path | None = None


def _str_list(v: Any, path: str) -> tuple[str, ...]:
    if not (isinstance(v, list) and all(isinstance(x, str) for x in v)):
        raise ConfigError.field(path, v, "must be a list of strings")
    return tuple(v)


def _check_keys(table: Mapping, allowed: Sequence[str], where: str) -> None:
    for k in table:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), list(allowed), n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(f"unknown key {where + '.' if where else ''}{k}; {hint}allowed: "
                              f"{', '.join(allowed)}", path=f"{where}.{k}" if where else str(k))


def finding_from_dict(raw: Mapping, name: str, path: Path | None = None) -> Finding:
    """Validate a parsed finding file.  Raises ConfigError naming the field."""
    _check_keys(raw, ("finding", "run", "ratio", "claim"), "")
    head = raw.get("finding")
    if not isinstance(head, Mapping):
        raise ConfigError("missing [finding] table", path="finding")
    _check_keys(head, ("title", "claim", "method", "scenario", "set", "show", "figures"), "finding")
    for key in ("title", "claim"):
        if not isinstance(head.get(key), str) or not head[key].strip():
            raise ConfigError.field(f"finding.{key}", head.get(key), "must be a non-empty string")
    runs_raw = raw.get("run")
    if not (isinstance(runs_raw, list) and runs_raw):
        raise ConfigError("at least one [[run]] table is needed", path="run")
    claim = raw.get("claim", {})
    if not isinstance(claim, Mapping):
        raise ConfigError.field("claim", claim, "must be a table")
    runs = []
    for i, r in enumerate(runs_raw):
        where = f"run[{i}]"
        if not isinstance(r, Mapping):
            raise ConfigError.field(where, r, "must be a table")
        _check_keys(r, ("name", "set", "measure", "simulate"), where)
        rname = r.get("name")
        if not (isinstance(rname, str) and rname.isidentifier()):
            raise ConfigError.field(f"{where}.name", rname, "must be an identifier (letters, digits, _)")
        measures = _str_list(r.get("measure", []), f"{where}.measure")
        for m in measures:
            if m not in MEASURES:
                raise ConfigError.field(f"{where}.measure", m, f"must be one of {', '.join(MEASURES)}")
        bounds = None
        if isinstance(claim.get(rname), Mapping):
            bounds = bounds_from_dict({"bounds": dict(claim[rname])}, label=f"claim.{rname}")
        sim = r.get("simulate", True)
        if not isinstance(sim, bool):
            raise ConfigError.field(f"{where}.simulate", sim, "must be true or false")
        if not sim and (bounds is not None or not measures):
            raise ConfigError.field(f"{where}.simulate", sim,
                                    "false needs a measure and no [claim.<run>] (there are no metrics)")
        runs.append(RunSpec(rname, _str_list(r.get("set", []), f"{where}.set"), measures, bounds, sim))
    names = [r.name for r in runs]
    if len(set(names)) != len(names):
        raise ConfigError.field("run.name", names, "must be unique")
    ratios: dict[str, tuple[str, str]] = {}
    for k, v in dict(raw.get("ratio", {})).items():
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v)):
            raise ConfigError.field(f"ratio.{k}", v, 'must be ["numerator", "denominator"] quantities')
        ratios[k] = (v[0], v[1])
    figures = _str_list(head.get("figures", []), "finding.figures")
    for fr in figures:
        if fr not in names:
            raise ConfigError.field("finding.figures", fr, f"must name a run ({', '.join(names)})")
    limits: dict[str, tuple[str, str, float]] = {}
    for k, v in claim.items():
        if isinstance(v, Mapping):
            if k not in names:
                raise ConfigError.field(f"claim.{k}", k, f"must name a run ({', '.join(names)})")
            continue
        rel = "max" if k.endswith("_max") else "min" if k.endswith("_min") else None
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if rel is None or not ok:
            raise ConfigError.field(f"claim.{k}", v,
                                    "must be <quantity>_max or <quantity>_min = a finite number")
        limits[k] = (k[:-4], rel, float(v))
    if not limits and not any(r.bounds for r in runs):
        raise ConfigError("the claim has no checks: add [claim] limits", path="claim")
    return Finding(name, head["title"].strip(), head["claim"].strip(), str(head.get("method", "")).strip(),
                   head.get("scenario"), _str_list(head.get("set", []), "finding.set"), tuple(runs),
                   ratios, limits, _str_list(head.get("show", []), "finding.show"), figures, path)


def load_finding(source: str | Path) -> Finding:
    """A finding by path or by shipped name (`eq28_sign_typo`)."""
    path = Path(source)
    if not path.exists() and len(path.parts) == 1:
        path = findings_dir() / (path.name if path.suffix else path.name + ".toml")
    if not path.is_file():
        known = ", ".join(available())
        raise ConfigError(f"no finding {str(source)!r}; shipped: {known}", path="findings")
    raw = read_toml(path, "finding file")
    try:
        return finding_from_dict(raw, path.stem, path)
    except ConfigError as e:
        raise e.with_context(str(path)) from None


def available() -> list[str]:
    """Names of the shipped findings, sorted."""
    return sorted(p.stem for p in findings_dir().glob("*.toml"))


# --------------------------------------------------------------------------------------------------
# running


@dataclass
class Check:
    quantity: str
    relation: str  # "max" | "min" | "eq"
    limit: Any
    measured: Any
    holds: bool
    unit: str = ""


@dataclass
class FindingResult:
    finding: Finding
    values: dict[str, Any] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    trajectories: dict[str, Any] = field(default_factory=dict)
    wall_time: float = 0.0
    error: str = ""

    @property
    def holds(self) -> bool:
        return not self.error and bool(self.checks) and all(c.holds for c in self.checks)


def _limit_key(q: str) -> str:
    return q.replace(".", "_")


def _num(v: Any) -> float | None:
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


def finding_scenarios(f: Finding) -> list:
    """The validated scenario of each run of a finding (raises ConfigError naming the field)."""
    from harness.config.load import load_scenario
    from harness.loop.controllers import resolve_controller
    from harness.plant import validate_plant

    out = []
    for r in f.runs:
        try:
            scn = load_scenario(f.scenario, [*f.set, *r.set])
            validate_plant(scn)
            out.append(resolve_controller(scn))
        except ConfigError as e:
            raise e.with_context(f"finding {f.name}, run {r.name}") from None
    return out


def run_finding(f: Finding, keep_trajectories: bool = False, scenarios: list | None = None) -> FindingResult:
    """Run every run of a finding and check its claim.  A bad scenario override raises ConfigError
    before anything runs; an exception while running is the result's `error` (the finding then does
    not hold)."""
    res = FindingResult(f)
    t0 = time.perf_counter()
    scenarios = finding_scenarios(f) if scenarios is None else scenarios
    try:
        _run(f, scenarios, res, keep_trajectories)
    except Exception as e:  # noqa: BLE001 - reported as the finding's error, the other findings go on
        res.error = f"{type(e).__name__}: {e}"
    res.wall_time = time.perf_counter() - t0
    return res


def _run(f: Finding, scenarios: list, res: FindingResult, keep_trajectories: bool) -> None:
    from harness.loop import simulate
    from harness.loop.metrics import compute_metrics

    for r, scn in zip(f.runs, scenarios, strict=True):
        traj, metrics = None, {}
        if r.simulate:
            traj = simulate(scn, progress=False, overlap=False)
            metrics = compute_metrics(traj, scn)
        for k, v in metrics.items():
            res.values[f"{r.name}.{k}"] = v
        for m in r.measure:
            for k, v in MEASURES[m](scn, traj).items():
                res.values[f"{r.name}.{k}"] = v
        if r.bounds is not None:
            bad = {v.bound: v for v in check_bounds(metrics, r.bounds)}
            res.checks += _bounds_checks(r.name, r.bounds, metrics, bad)
        if keep_trajectories:
            res.trajectories[r.name] = (scn, traj)
    for name, (a, b) in f.ratios.items():
        na, nb = _num(res.values.get(a)), _num(res.values.get(b))
        res.values[name] = na / nb if na is not None and nb not in (None, 0.0) else None
    by_key = {_limit_key(q): q for q in res.values}
    for key, rel, lim in f.limits.values():
        q = by_key.get(key, key)
        v = _num(res.values.get(q))
        ok = v is not None and math.isfinite(v) and (v <= lim if rel == "max" else v >= lim)
        res.checks.append(Check(q, rel, lim, v, ok, _unit(q).strip()))


def _bounds_checks(run: str, bounds: Bounds, metrics: Mapping, bad: Mapping[str, Violation]) -> list[Check]:
    from dataclasses import fields

    from harness.config.bounds import FLAG_BOUNDS, NUMERIC_BOUNDS

    out = []
    for fl in fields(bounds):
        key, limit = fl.name, getattr(bounds, fl.name)
        if key in NUMERIC_BOUNDS and limit is not None:
            metric, rel, unit, _ = NUMERIC_BOUNDS[key]
            out.append(Check(f"{run}.{metric}", rel, limit, metrics.get(metric), key not in bad, unit))
        elif key in FLAG_BOUNDS and limit:
            metric = "status" if key == "status_ok" else "mujoco_warnings"
            want = "ok" if key == "status_ok" else 0
            out.append(Check(f"{run}.{metric}", "eq", want, metrics.get(metric), key not in bad))
    return out


def run_findings(names: Iterable[str] = (), say: Callable[[str], None] = lambda s: None,
                 keep_trajectories: bool = False) -> list[FindingResult]:
    """Load (all before running any) and run the named findings (default: every shipped one)."""
    findings = [load_finding(n) for n in (list(names) or available())]
    scenarios = [finding_scenarios(f) for f in findings]  # every run validated before any runs
    out = []
    for f, scns in zip(findings, scenarios, strict=True):
        say(f"finding {f.name}: {len(f.runs)} run(s)")
        out.append(run_finding(f, keep_trajectories, scns))
    return out


# --------------------------------------------------------------------------------------------------
# reporting


def fmt(v: Any) -> str:
    """A measured value in 4 significant digits (strings and None as they are)."""
    n = _num(v)
    if n is None:
        return "not measured" if v is None else str(v)
    if n == 0 or 1e-3 <= abs(n) < 1e4:
        return f"{n:.4g}"
    return f"{n:.3e}"


MEASURE_UNITS = {"diverged_at": "s", "arc_departure": "mm", "chained_cc_tip": "mm", "settle_3s_error": "mm",
                 "settle_time": "s", "law_gap": "mm", "free_chain_error": "mm", "cc_chain_error": "mm"}


def _unit(quantity: str) -> str:
    """' <unit>' of a run metric (from the bounds table) or a derived measurement, else ''."""
    from harness.config.bounds import NUMERIC_BOUNDS

    key = quantity.rsplit(".", 1)[-1]
    units = {metric: unit for metric, _, unit, _ in NUMERIC_BOUNDS.values() if unit}
    unit = units.get(key) or MEASURE_UNITS.get(key, "")
    return f" {unit}" if unit else ""


def check_text(c: Check) -> str:
    rel = {"max": "<=", "min": ">=", "eq": "=="}[c.relation]
    unit = f" {c.unit}" if c.unit else ""
    return f"{c.quantity} = {fmt(c.measured)}{unit} ({rel} {fmt(c.limit)}{unit})"


def report_text(r: FindingResult) -> str:
    """Claim / measured / holds for one finding, as printed by `teleop findings`."""
    verdict = "holds" if r.holds else "DOES NOT HOLD"
    lines = [f"{r.finding.name}: {verdict} ({r.wall_time:.1f} s)", f"  claim: {r.finding.claim}"]
    if r.error:
        lines.append(f"  error: {r.error}")
    lines += [f"  {'ok ' if c.holds else 'BAD'} {check_text(c)}" for c in r.checks]
    lines += [f"  also {q} = {fmt(r.values.get(q))}{_unit(q)}" for q in r.finding.show]
    return "\n".join(lines)


def findings_table(results: Sequence[FindingResult]) -> str:
    """The markdown table the docs' findings page includes."""
    rows = ["| finding | claim | measured (limit) | holds |", "|---|---|---|---|"]
    for r in results:
        parts = [f"error: {r.error}"] if r.error else []
        parts += [check_text(c) for c in r.checks]
        parts += [f"{q} = {fmt(r.values.get(q))}{_unit(q)}" for q in r.finding.show]
        measured = "<br>".join(p.replace("|", "\\|") for p in parts)
        claim = r.finding.claim.replace("|", "\\|").replace("\n", " ")
        rows.append(f"| **{r.finding.title}** (`{r.finding.name}`) | {claim} | {measured} | "
                    f"{'yes' if r.holds else '**no**'} |")
    return "\n".join(rows) + "\n"


def write_outputs(results: Sequence[FindingResult], table: Path, figures: Path,
                  combined: bool = True) -> list[Path]:
    """Write the findings table (markdown; also `<table stem>-<finding>.md` per finding) and, for the
    runs a finding names in `figures`, the paper's Figs 2-4 as
    `<figures>/<finding>-<run>-fig{2,3,4}.png` (each file atomically).  combined=False writes only the
    per-finding tables (a rerun of some findings must not replace the table of all).  Returns the paths."""
    from harness.config.textio import write_atomic
    from harness.output.plots import fig_beta, fig_e1, fig_e2

    written = []
    for r in results:
        for run in r.finding.figures:
            if run not in r.trajectories:
                continue
            _, traj = r.trajectories[run]
            figures.mkdir(parents=True, exist_ok=True)
            for tag, draw in (("fig2_e1", fig_e1), ("fig3_e2", fig_e2), ("fig4_beta", fig_beta)):
                written.append(draw(traj, figures / f"{r.finding.name}-{run}-{tag}.png"))
    table.parent.mkdir(parents=True, exist_ok=True)
    for r in results:  # one table per finding, for pages that show a single one
        one = table.with_name(f"{table.stem}-{r.finding.name}.md")
        written.append(write_atomic(one, findings_table([r])))
    if combined:
        written.append(write_atomic(table, findings_table(results)))
    return written


__all__ = ["MEASURES", "Finding", "FindingResult", "available", "finding_scenarios", "findings_dir",
           "findings_table",
           "load_finding", "report_text", "run_finding", "run_findings", "write_outputs"]
