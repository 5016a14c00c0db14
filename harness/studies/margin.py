"""Robustness margins (`teleop margin`; method in docs/stability.md): per mismatch parameter the largest
deviation from the nominal scenario each way that passes a bounds file (bracketing, bisection, probes).
Runs go through the sweep executor and are journaled in `results.jsonl` (a rerun resumes)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from harness.config.bounds import FLAGS, Bounds, check_bounds, limit_of
from harness.config.controller import resolve_controller
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import Scenario
from harness.config.textio import toml_literal
from harness.studies.cases import _get as get_field
from harness.studies.cases import _scaled, scenario_id
from harness.studies.study import Case


@dataclass(frozen=True)
class Param:
    """A mismatch parameter: `keys` (scenario fields moved together), `mode` "scale" (factor of each
    key's value), "rate" (divides them) or "value", search range [lo, hi], plants (None = all)."""

    name: str
    keys: tuple[str, ...]
    mode: str
    lo: float
    hi: float
    integer: bool = False
    plants: tuple[str, ...] | None = None
    unit: str = "x"
    exponents: tuple[float, ...] | None = None  # scale mode: key i is scaled by level ** exponents[i]


PARAMS: dict[str, Param] = {p.name: p for p in (
    Param("slave_mass", ("plant.slave.masses",), "scale", 0.05, 20.0),  # every slave section's mass
    Param("bending_stiffness", ("plant.slave.bending_stiffness",), "scale", 0.05, 20.0),  # Kb
    Param("extension_stiffness", ("plant.slave.extension_stiffness",), "scale", 0.05, 20.0),  # Ke
    Param("material_damping", ("plant.bending_viscosity", "plant.extension_viscosity"), "scale", 0.01, 100.0,
          plants=("mujoco", "cosserat")),  # eta_b, eta_a of the chain / rod
    Param("segments", ("plant.segments",), "value", 1, 64, integer=True, plants=("mujoco",), unit=""),
    Param("control_rate", ("control_dt", "plant.physics_dt"), "rate", 0.1, 10.0),  # both divided by it
    # not on the analytic plant: its compiled loop does not apply plant.actuation_delay
    Param("delay", ("plant.actuation_delay",), "value", 0.0, 0.1, unit="s", plants=("mujoco", "cosserat")),
    Param("noise_snr", ("snr_db",), "value", 0.0, 200.0, unit="dB"),  # sensing noise; lower = noisier
    Param("master_mass", ("plant.master.masses",), "scale", 0.05, 20.0),  # both master links
)}
DEFAULT_PARAMS = tuple(PARAMS)


def param_of(name: str) -> Param:
    """A named parameter of PARAMS, or any scenario key (dotted path) as a scale factor in [0.05, 20]."""
    if name in PARAMS:
        return PARAMS[name]
    if "." in name or name in ("control_dt", "duration"):
        return Param(name, (name,), "scale", 0.05, 20.0)
    raise ConfigError.field("--param", name, f"expected one of {', '.join(PARAMS)} or a dotted scenario key")


def servo_note(scn: Scenario, names: Sequence[str]) -> str:
    """One line when a margin over the slave's inertia runs on the servo-actuated MuJoCo chain, else ''."""
    hidden = sorted(n for n in names if n == "slave_mass" or n.startswith(("plant.slave.masses",
                                                                           "plant.slave.slice_inertia")))
    if scn.plant.actuation != "servo" or scn.plant.kind != "mujoco" or not hidden:
        return ""
    return (f"servo actuation: the position servos hide the slave's inertia; a margin over "
            f"{', '.join(hidden)} says little about the controller's dynamics model")


def _get(scn: Scenario, key: str) -> Any:
    return get_field(scn, tuple(key.split(".")), scn, key)


def nominal_value(scn: Scenario, p: Param) -> float | None:
    """The nominal point of p: 1 for a scale or rate; the scenario's value for a value parameter (a vector
    field: its first entry; None for an unset SNR)."""
    v = 1.0 if p.mode in ("scale", "rate") else _get(scn, p.keys[0])
    return None if v is None else float(v[0] if isinstance(v, tuple | list) else v)


def overrides_at(scn: Scenario, p: Param, level: float) -> list[str]:
    """Scenario overrides putting p at `level` (scale factor or value)."""
    out = []
    for key in p.keys:
        if p.mode == "rate":
            v = _get(scn, key) / level
        elif p.mode == "scale":
            nom = _get(scn, key)
            s = level if p.exponents is None else level ** p.exponents[p.keys.index(key)]
            v = _scaled(list(nom) if isinstance(nom, tuple) else nom, s, key)
        else:
            v = int(round(level)) if p.integer else float(level)
            cur = _get(scn, key)
            if isinstance(cur, tuple):
                v = [v] * len(cur)
        out.append(f"{key}={toml_literal(v)}")
    return out


def applies(scn: Scenario, p: Param) -> str:
    """'' if p can be searched on scn, else why not (one line)."""
    if p.plants is not None and scn.plant.kind not in p.plants:
        return f"not a parameter of the {scn.plant.kind} plant"
    if nominal_value(scn, p) is None:
        return "unset in the scenario (no nominal value)"
    for key in p.keys if p.mode == "scale" else ():
        v = _get(scn, key)
        if all(float(x) == 0.0 for x in (v if isinstance(v, tuple | list) else [v])):
            return f"{key} is 0 in the scenario (a scale factor cannot move it)"
    return ""


@dataclass
class Search:
    """Bracketing (x2 steps), bisection and probes from the nominal level towards `limit` (one range end):
    `next_levels()` to run, `feed(level, passed)` their outcomes, `done` when the edge and probes are."""

    param: Param
    nominal: float
    limit: float
    rtol: float
    atol: float
    probes: int
    quantum: float = 0.0  # values live on this grid (delay: control_dt); 0 = continuous
    side: str = "upper"
    last_pass: float = float("nan")
    first_fail: float | None = None
    state: str = "bracket"
    probe_levels: list = field(default_factory=list)
    failed_probes: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.last_pass = self.nominal
        self.log = self.param.mode in ("scale", "rate")

    # distance along the ray: log(level / nominal) for scales, level - nominal for values
    def _u(self, level: float) -> float:
        return math.log(level / self.nominal) if self.log else level - self.nominal

    def _level(self, u: float) -> float:
        x = self.nominal * math.exp(u) if self.log else self.nominal + u
        if self.param.integer:
            return float(round(x))
        if self.quantum > 0:
            return round(round(x / self.quantum) * self.quantum, 12)
        return float(f"{x:.6g}")

    def _narrow(self) -> bool:
        a, b = self.last_pass, self.first_fail
        if self.param.integer or self.quantum > 0:
            q = 1.0 if self.param.integer else self.quantum
            return abs(b - a) <= q * (1 + 1e-9)
        if self.log:
            return max(a, b) / min(a, b) <= 1.0 + self.rtol
        return abs(b - a) <= self.atol

    def next_levels(self) -> list[float]:
        if self.state == "bracket" and self.last_pass != self.limit:
            u = self._u(self.last_pass)
            sign = 1.0 if self.limit > self.nominal else -1.0
            if self.log:  # x2 per step
                u_next = u + sign * math.log(2.0)
            elif u == 0:  # the smallest step first, then doubling distances
                first = 1.0 if self.param.integer else self.quantum or abs(self.limit - self.nominal) / 64
                u_next = sign * first
            else:
                u_next = 2.0 * u
            nxt = self._level(u_next)
            if (nxt - self.limit) * sign >= 0 or nxt == self.last_pass:
                nxt = self.limit
            return [nxt]
        if self.state == "bisect" and not self._narrow():
            mid = self._level(0.5 * (self._u(self.last_pass) + self._u(self.first_fail)))
            if mid not in (self.last_pass, self.first_fail):
                return [mid]
        if self.state not in ("bracket", "bisect"):
            return []
        # the edge is found: probes inside the margin
        ue = self._u(self.last_pass)
        self.probe_levels = sorted({self._level(ue * (i + 1) / (self.probes + 1)) for i in range(self.probes)}
                                   - {self.nominal, self.last_pass})
        self.state = "probing" if self.probe_levels else "done"
        return self.probe_levels

    def feed(self, level: float, passed: bool) -> None:
        if self.state == "probing":
            if not passed:
                self.failed_probes.append(level)
            return
        if passed:
            self.last_pass = level
        else:
            self.first_fail = level
            self.state = "bisect"

    def end_round(self) -> None:
        if self.state == "probing":
            self.state = "done"

    @property
    def done(self) -> bool:
        return self.state == "done"


@dataclass
class Outcome:
    """The journal's record of one run: passed, the violations (text), the first violated bound and the
    measured metrics."""

    passed: bool
    status: str
    violations: list[str]
    first: str
    metrics: dict


def _outcome(row: dict, bounds: Bounds) -> Outcome:
    metrics = dict(row.get("metrics") or {})
    metrics.setdefault("status", row.get("status"))
    if row.get("status") == "error":
        return Outcome(False, "error", [row.get("message", "error")], "error", metrics)
    v = check_bounds(metrics, bounds)
    return Outcome(not v, str(row.get("status")), [str(x) for x in v], v[0].bound if v else "", metrics)


class Journal:
    """The runs of a margin search: results.jsonl rows by case id (the scenario hash), resumable."""

    def __init__(self, out: Path | None):
        from harness.studies.sweep import RESULTS, ResultsWriter, read_results

        path = None if out is None else Path(out) / RESULTS
        self.rows: dict[str, dict] = {} if path is None else read_results(path)
        self.writer = None if path is None else ResultsWriter(path)

    def add(self, row: dict) -> None:
        self.rows.setdefault(row["case_id"], row)
        if self.writer is not None:
            self.writer.append(row)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def run_levels(requests: list[tuple[Param, float]], ctx: dict) -> dict[tuple[str, float], Outcome]:
    """Outcome of each (param, level), from the journal or run through the executor in one batch."""
    from harness.studies.executor import run_case, run_cases
    from harness.studies.sweep import make_row

    journal: Journal = ctx["journal"]
    bounds: Bounds = ctx["bounds"]
    cases, keys = [], {}
    for p, level in requests:
        ovr = overrides_at(ctx["scn"], p, level)
        s = resolve_controller(load_scenario(ctx["source"], [*ctx["set"], *ovr]))
        cid = scenario_id(s)
        c = Case(cid, {p.name: level}, tuple(ovr), dataclasses.replace(s, name=f"margin-{cid}"))
        keys[p.name, level] = c.case_id
        if c.case_id not in journal.rows and all(x.case_id != c.case_id for x in cases):
            cases.append(c)
    if cases:
        def on_result(case, res) -> None:
            journal.add(make_row(case, res))
            ctx["say"](f"  {next(iter(case.params.items()))}: {res.get('status')}")

        run_cases(ctx["runner"], ctx["case_fn"] or run_case, cases, ctx["metrics"], False, on_result)
    return {k: _outcome(journal.rows[cid], bounds) for k, cid in keys.items()}


@dataclass
class Margin:
    """One row of the margins table: `param`, its nominal point, and per direction ("lower", "upper") a dict
    (`_side`): margin, first failing level, first violated bound, its metric at both, failed probes."""

    param: str
    nominal: float | None
    unit: str
    note: str = ""
    sides: dict = field(default_factory=dict)


def _side(search: Search, outcomes: dict) -> dict:
    p = search.param
    at_pass = outcomes.get((p.name, search.last_pass))
    at_fail = outcomes.get((p.name, search.first_fail)) if search.first_fail is not None else None
    first = at_fail.first if at_fail else ""
    metric = FLAGS.get(first) or (limit_of(first)[0] if first.endswith(("_max", "_min")) else first)
    return {"margin": search.last_pass, "fail": search.first_fail, "first_bound": first,
            "bound_metric": metric, "metric_at_margin": at_pass.metrics.get(metric) if at_pass else None,
            "metric_at_fail": at_fail.metrics.get(metric) if at_fail else None,
            "violations_at_fail": at_fail.violations if at_fail else [],
            "status_at_fail": at_fail.status if at_fail else None,
            "range_end": search.first_fail is None, "non_monotone": list(search.failed_probes),
            "probes": list(search.probe_levels)}


def margins(scn: Scenario, bounds: Bounds, params: Sequence[str | Param] = DEFAULT_PARAMS, *, source=None,
            base_set: Sequence[str] = (), rtol: float = 0.05, atol: float | None = None, probes: int = 2,
            out: Path | None = None, workers: int | None = None, scheduler: str | None = None,
            executor: str = "processes", say: Callable[[str], None] = lambda s: None,
            case_fn: Callable | None = None) -> list[Margin]:
    """Margins of `scn` (file `source` with overrides `base_set`, from which the cases are loaded) against
    `bounds` per parameter.  rtol: scale edges (s_fail / s_pass - 1); atol: value edges (default 1/100 of
    the range; delays and integers exact); probes: points per side inside the margin.  ConfigError for
    bad input or a nominal scenario that fails the bounds."""
    from harness.studies.executor import Runner

    if not (0 < rtol < 1):
        raise ConfigError.field("rtol", rtol, "expected a relative tolerance in (0, 1)")
    plist = [n if isinstance(n, Param) else param_of(n) for n in params]
    limits = [limit_of(f.name)[0] for f in dataclasses.fields(bounds)
              if f.name.endswith(("_max", "_min")) and getattr(bounds, f.name) is not None]
    journal = Journal(out)
    runner = Runner(workers, scheduler, "dask" if scheduler else executor)
    ctx = {"journal": journal, "bounds": bounds, "source": source, "set": list(base_set), "scn": scn,
           "runner": runner, "metrics": sorted({*limits, "mujoco_warnings", "status"}), "say": say,
           "case_fn": case_fn}
    try:
        rows: dict[str, Margin] = {}
        searches: list[Search] = []
        nominal_p = PARAMS["slave_mass"]  # at scale 1: the nominal scenario on every plant
        for p in plist:
            why = applies(scn, p)
            nom = nominal_value(scn, p)
            rows[p.name] = Margin(p.name, nom, p.unit, note=why)
            if why:
                continue
            quantum = scn.control_dt if p.name == "delay" else 0.0
            tol = atol if atol is not None else (p.hi - p.lo) / 100
            for side, lim in (("lower", p.lo), ("upper", p.hi)):
                if (lim - nom) * (1 if side == "upper" else -1) > 0:
                    searches.append(Search(p, nom, lim, rtol, tol, probes, quantum, side=side))
                    continue
                rows[p.name].sides[side] = {"margin": nom, "fail": None, "first_bound": "", "range_end": True,
                                            "non_monotone": [], "probes": [],
                                            "note": "nominal at the range end"}
        outcomes: dict = {}
        if searches:  # the nominal point must pass
            first = run_levels([(nominal_p, 1.0)], ctx)[nominal_p.name, 1.0]
            if not first.passed:
                raise ConfigError(f"the nominal scenario fails the bounds ({'; '.join(first.violations)}); "
                                  "no margin to search")
            outcomes.update({(p.name, nominal_value(scn, p)): first for p in plist})
        rnd = 0
        while not all(s.done for s in searches):
            rnd += 1
            req = [(s, lv) for s in searches if not s.done for lv in s.next_levels()]
            if req:
                say(f"round {rnd}: {len(req)} run(s)")
                res = run_levels([(s.param, lv) for s, lv in req], ctx)
                outcomes.update(res)
                for s, lv in req:
                    s.feed(lv, res[s.param.name, lv].passed)
            for s in searches:
                s.end_round()
        for s in searches:
            rows[s.param.name].sides[s.side] = _side(s, outcomes)
        return [rows[p.name] for p in plist]
    finally:
        runner.close()
        journal.close()


def ray(p1: Param, p2: Param, angle: float) -> Param:
    """The scale parameter moving p1 by s ** cos(angle) and p2 by s ** sin(angle) (a ray in the plane of
    log p1, log p2), s in [1, min(p1.hi, p2.hi)]."""
    if p1.mode != "scale" or p2.mode != "scale":
        raise ConfigError.field("--pair", f"{p1.name},{p2.name}", "both parameters must be scale factors")
    c, s = math.cos(angle), math.sin(angle)
    keys = p1.keys + p2.keys
    exps = tuple(c for _ in p1.keys) + tuple(s for _ in p2.keys)
    return Param(f"{p1.name}|{p2.name}@{math.degrees(angle):.0f}deg", keys, "scale", 1.0,
                 min(p1.hi, 1 / p1.lo, p2.hi, 1 / p2.lo), plants=p1.plants or p2.plants, exponents=exps)


def edge_trace(scn: Scenario, bounds: Bounds, pair: tuple[str, str], n_rays: int = 8, **kw) -> list[dict]:
    """The 2-D pass/fail edge of two scale parameters: `margins` along n_rays rays in the (log p1, log p2)
    plane.  Rows {angle_deg, p1, p2 (at the margin), fail_p1, fail_p2 (None at a range end), first_bound,
    non_monotone}."""
    p1, p2 = param_of(pair[0]), param_of(pair[1])
    rays = [ray(p1, p2, 2 * math.pi * i / n_rays) for i in range(n_rays)]
    rows = margins(scn, bounds, rays, **kw)
    out = []
    for r, m in zip(rays, rows, strict=True):
        d = m.sides.get("upper", {})
        c, s = r.exponents[0], r.exponents[-1]
        lv, fv = d.get("margin", 1.0), d.get("fail")
        out.append({"angle_deg": round(math.degrees(math.atan2(s, c)) % 360, 6), "p1": lv ** c, "p2": lv ** s,
                    "fail_p1": None if fv is None else fv ** c, "fail_p2": None if fv is None else fv ** s,
                    "first_bound": d.get("first_bound", ""), "non_monotone": bool(d.get("non_monotone"))})
    return out


__all__ = ["DEFAULT_PARAMS", "Margin", "PARAMS", "Param", "Search", "edge_trace", "margins", "param_of",
           "ray"]
