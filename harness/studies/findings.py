"""Findings: the harness's scientific results as small runnable files (`findings/`, file format in
docs/findings.md), rerun by `teleop findings`; `findings_table` renders the docs' markdown table."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from harness.config.assets import asset_dir
from harness.config.bounds import FLAGS, Bounds, Violation, bounds_from_dict, check_bounds, limit_of
from harness.config.errors import ConfigError
from harness.config.metrics import METRIC_UNITS, value_unit
from harness.config.schema import unknown_keys
from harness.config.textio import read_toml
from harness.studies.finding_measures import MEASURE_UNITS, MEASURES


def findings_dir() -> Path:
    """Folder of the shipped finding files (package data, else the checkout's `findings/`)."""
    return asset_dir("findings")


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
    bad = {k: v for k, v in table.items() if k not in allowed}
    if bad:
        raise unknown_keys(f"{where}." if where else "", bad, allowed)


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


def _num(v: Any) -> float | None:
    v = v.item() if hasattr(v, "item") else v
    return None if isinstance(v, bool) or not isinstance(v, (int, float)) else float(v)


def finding_scenarios(f: Finding) -> list:
    """The validated scenario of each run of a finding (raises ConfigError naming the field)."""
    from harness.config.controller import resolve_controller
    from harness.config.load import load_scenario
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
    """Run every run of a finding and check its claim.  A bad override raises ConfigError before anything
    runs; an exception while running is the result's `error` (the finding does not hold)."""
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
            traj = simulate(scn, progress=False)
            metrics = compute_metrics(traj, scn)
        for part in (metrics, *(MEASURES[m](scn, traj) for m in r.measure)):
            res.values.update({f"{r.name}.{k}": v for k, v in part.items()})
        if r.bounds is not None:
            bad = {v.bound: v for v in check_bounds(metrics, r.bounds)}
            res.checks += _bounds_checks(r.name, r.bounds, metrics, bad)
        if keep_trajectories:
            res.trajectories[r.name] = (scn, traj)
    for name, (a, b) in f.ratios.items():
        na, nb = _num(res.values.get(a)), _num(res.values.get(b))
        res.values[name] = na / nb if na is not None and nb not in (None, 0.0) else None
    by_key = {q.replace(".", "_"): q for q in res.values}
    for key, rel, lim in f.limits.values():
        q = by_key.get(key, key)
        v = _num(res.values.get(q))
        ok = v is not None and math.isfinite(v) and (v <= lim if rel == "max" else v >= lim)
        res.checks.append(Check(q, rel, lim, v, ok, _unit(q).strip()))


def _bounds_checks(run: str, bounds: Bounds, metrics: Mapping, bad: Mapping[str, Violation]) -> list[Check]:
    out = []
    for fl in fields(bounds):
        key, limit = fl.name, getattr(bounds, fl.name)
        if key in FLAGS:
            if limit:
                metric = FLAGS[key]
                want = "ok" if metric == "status" else 0
                out.append(Check(f"{run}.{metric}", "eq", want, metrics.get(metric), key not in bad))
        elif key.endswith(("_max", "_min")) and limit is not None:
            metric, rel, unit = limit_of(key)
            out.append(Check(f"{run}.{metric}", rel, limit, metrics.get(metric), key not in bad, unit))
    return out


def run_findings(names: Iterable[str] = (), keep_trajectories: bool = False,
                 on_result: Callable[[FindingResult], None] = lambda r: None) -> list[FindingResult]:
    """Load and validate the named findings (default: every shipped one; all before any runs), run
    them one after another and return their results; `on_result` gets each as it is done."""
    findings = [load_finding(n) for n in (list(names) or available())]
    scenarios = [finding_scenarios(f) for f in findings]
    out = []
    for f, scns in zip(findings, scenarios, strict=True):
        out.append(run_finding(f, keep_trajectories, scns))
        on_result(out[-1])
    return out


def fmt(v: Any) -> str:
    """A measured value in 4 significant digits (strings and None as they are)."""
    n = _num(v)
    if n is None:
        return "not measured" if v is None else str(v)
    if n == 0 or 1e-3 <= abs(n) < 1e4:
        return f"{n:.4g}"
    return f"{n:.3e}"


def _unit(quantity: str) -> str:
    """' <unit>' of a run metric (`METRIC_UNITS`) or a derived measurement (`MEASURE_UNITS`), else ''."""
    key = quantity.rsplit(".", 1)[-1]
    unit = value_unit(key) if key in METRIC_UNITS else MEASURE_UNITS.get(key, "")
    return f" {unit}" if unit else ""


def check_text(c: Check) -> str:
    rel = {"max": "<=", "min": ">=", "eq": "=="}[c.relation]
    unit = f" {c.unit}" if c.unit else ""
    return f"{c.quantity} = {fmt(c.measured)}{unit} ({rel} {fmt(c.limit)}{unit})"


def _parts(r: FindingResult, ok: str = "", bad: str = "", also: str = "") -> list[str]:
    """The error, the checks (prefixed ok / bad) and the `show` quantities (prefixed also) of a result."""
    parts = [f"error: {r.error}"] if r.error else []
    parts += [f"{ok if c.holds else bad}{check_text(c)}" for c in r.checks]
    return parts + [f"{also}{q} = {fmt(r.values.get(q))}{_unit(q)}" for q in r.finding.show]


def report_text(r: FindingResult) -> str:
    """Claim / measured / holds for one finding, as printed by `teleop findings`."""
    verdict = "holds" if r.holds else "DOES NOT HOLD"
    lines = [f"{r.finding.name}: {verdict} ({r.wall_time:.1f} s)", f"  claim: {r.finding.claim}"]
    return "\n".join(lines + [f"  {p}" for p in _parts(r, "ok  ", "BAD ", "also ")])


def findings_table(results: Sequence[FindingResult]) -> str:
    """The markdown table the docs' findings page includes."""
    rows = ["| finding | claim | measured (limit) | holds |", "|---|---|---|---|"]
    for r in results:
        parts = _parts(r)
        measured = "<br>".join(p.replace("|", "\\|") for p in parts)
        claim = r.finding.claim.replace("|", "\\|").replace("\n", " ")
        rows.append(f"| **{r.finding.title}** (`{r.finding.name}`) | {claim} | {measured} | "
                    f"{'yes' if r.holds else '**no**'} |")
    return "\n".join(rows) + "\n"


def write_outputs(results: Sequence[FindingResult], table: Path, figures: Path,
                  combined: bool = True) -> list[Path]:
    """Write the findings table (also `<table stem>-<finding>.md` per finding; combined=False: only those)
    and Figs 2-4 of the runs a finding names, `<figures>/<finding>-<run>-fig{2,3,4}.png` (returned)."""
    from harness.config.textio import write_atomic
    from harness.output.plots import fig_beta, fig_e1, fig_e2

    written = []
    for r in results:
        for run in (x for x in r.finding.figures if x in r.trajectories):
            traj = r.trajectories[run][1]
            figures.mkdir(parents=True, exist_ok=True)
            for tag, draw in (("fig2_e1", fig_e1), ("fig3_e2", fig_e2), ("fig4_beta", fig_beta)):
                written.append(draw(traj, figures / f"{r.finding.name}-{run}-{tag}.png"))
    table.parent.mkdir(parents=True, exist_ok=True)
    for r in results:  # one table per finding, for pages that show a single one
        written.append(write_atomic(table.with_name(f"{table.stem}-{r.finding.name}.md"),
                                    findings_table([r])))
    if combined:
        written.append(write_atomic(table, findings_table(results)))
    return written


__all__ = ["MEASURES", "Finding", "FindingResult", "available", "finding_scenarios", "findings_dir",
           "findings_table", "load_finding", "report_text", "run_finding", "run_findings", "write_outputs"]
