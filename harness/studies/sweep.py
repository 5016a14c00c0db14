"""Mismatch studies: vary the *plant* (and sensing) of a scenario, run every case in parallel, resume.

A mismatch study keeps the controller's nominal analytic model (`Scenario.master`, `Scenario.slave`,
`Scenario.gains`) and varies what the controller does not know: the plant (`plant.master`,
`plant.slave`, `plant.segments`, `plant.physics_dt`, `plant.actuation`, `plant.servo_frequency`,
`plant.servo_damping_ratio`, `plant.actuation_delay`, `plant.enforce_cc`, ...) and the sensing
(`snr_db`, `control_dt`).  Each case is one fully resolved `Scenario`; cases run through a
`concurrent.futures` executor (a process pool, or Dask distributed with `scheduler=ADDRESS`).

Study file (TOML)
-----------------
::

    [study]
    name = "mass_stiffness"            # output folder name; default: the file's stem
    description = "..."                # optional, free text
    scenario = "../scenarios/x.toml"   # base scenario, relative to the study file; default: built-in paper
    set = ["duration=5.0", "plant.kind='mujoco'"]   # scenario overrides applied to every case
    metrics = ["e2_rms", "e2_max", "beta_min"]      # metrics kept per case; default: all (METRIC_NAMES)
    record = {worst = 2, by = "e2_rms"}  # optional: .rrd recordings of the worst k cases by a metric;
                                         # order = "max" | "min" (default "min" for beta_min, else "max")

    [[factor]]
    name = "slave_mass"                # label in tables and plots; default: param
    param = "plant.slave.masses"       # dotted Scenario path; `plant.slave.masses[0]` = one section
    scale = [0.5, 0.75, 1.0, 1.25, 1.5]   # multiplicative factors (see below) ...
    # values = [4, 8, 16]                 # ... or absolute values (exactly one of scale / values)

    [[factor]]
    name = "bending"
    param = "plant.slave.bending_stiffness"
    scale = {random = "uniform", low = 0.5, high = 1.5}   # seeded random draws instead of a list

    [sampling]
    mode = "grid"      # "grid" (default) | "random"
    n = 20             # number of random draws (see below)
    seed = 0           # seed of the draws (default 0)

    [scenario]         # optional inline base scenario (instead of study.scenario); same keys as a
    duration = 5.0     # scenario file.  The `study.toml` written to the output folder uses it.

Factors
  * `param` is any field path of `Scenario` (`plant.slave.masses`, `plant.segments`, `snr_db`,
    `control_dt`, `plant.actuation`, `seed`, ...), optionally indexed (`plant.slave.masses[0]`,
    `plant.master.lengths[1]`).  The controller's model (`master.*`, `slave.*`) is rejected:
    a mismatch study varies `plant.master.*` / `plant.slave.*`.
  * `scale = s` multiplies the NOMINAL value: for `plant.master.*` / `plant.slave.*` that is the
    controller's model (`Scenario.master` / `Scenario.slave`), so s = 1 means "no mismatch"; for
    any other field it is the base scenario's value (after `set`).  Vector fields are scaled
    element-wise; integer fields must stay integers.
  * `values = [...]` are absolute values, passed to the scenario loader as given (a scalar given
    for a vector field is used for every entry).  The loader validates them.
  * Each case is the base scenario + `set` + one `key=value` override per varied field (an indexed
    factor writes the whole vector).  Untouched fields of `plant.slave` / `plant.master` keep the
    base plant's values, i.e. the nominal model when the base has none (`harness.io_config` rule).
  * Random draws (`{random = ...}` for `scale` or `values`): `uniform` / `loguniform` (`low`,
    `high`), `normal` (`mean`, `std`), `integers` (`low`, `high`, inclusive).  Each factor draws
    from its own generator seeded by (seed, factor name), so adding a factor leaves the others'
    draws unchanged.  Deterministic for a given seed (and numpy version).

Sampling
  * `grid`: cartesian product of the list factors.  If some factors are random, each grid point
    is combined with the same `n` draws of the random factors (common random numbers).
  * `random`: `n` cases; random factors are drawn, list factors are picked uniformly at random.

Outputs (folder `out`, default `runs/sweeps/<name>/`)
  * `results.jsonl`: one JSON object per finished case, appended by the parent process as soon as
    the case finishes (write + flush + fsync): `case_id`, `params` (factor -> value), `status`
    ("ok" | "diverged" | "error"), `message`, `metrics` (selected; non-finite numbers as null),
    `wall_time` (s, in the worker), `traceback` ("" unless an exception was caught).  A torn last
    line (crash while writing) is ignored and cut off before appending.
  * Resuming: re-running the same study into the same folder skips every case id already in the
    table, whatever its status (nothing runs twice; delete rows or the file to re-run).
  * `case_id`: the first 12 hex digits of the SHA-256 of the case's resolved scenario
    (`scenario_to_dict`, canonical JSON, without `name`): same study -> same ids in every process;
    a changed base scenario or `set` gives new ids (old rows stay in the table, unused).
  * `study.toml`: the resolved study (inline base scenario included) for provenance; it can be
    run again as a study file and gives the same case ids.
  * `summary.csv` (one row per case of the study), `metric_vs_<factor>.png` for each factor with
    more than one value, `heatmap_<a>__<b>.png` for each pair of list factors.
  * `.lock`: locked while a sweep runs; a second sweep into the same folder is refused (ConfigError).
  * `recordings/<case_id>.rrd` for the worst k cases (re-run after the sweep; the simulation is
    deterministic for a given seed).  The worker returns the file's bytes, so recordings also work
    on a remote Dask cluster without a shared file system.

Interrupts: Ctrl-C / SIGTERM cancel the pending cases, stop the workers and raise `SweepInterrupted`
(a `KeyboardInterrupt`); every finished row is already on disk and a later run resumes.  A worker
process that dies (segfault, out of memory) breaks the process pool: the cases that were in flight
are re-run one at a time in a fresh 1-process pool, the culprit is recorded with status "error".
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import dataclasses
import difflib
import hashlib
import itertools
import json
import logging
import math
import multiprocessing
import os
import re
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from tqdm import tqdm

from harness.config import Scenario
from harness.errors import ConfigError
from harness.io_config import load_scenario, scenario_to_dict
from harness.textio import jsonable, prepare_out_dir, read_toml, toml_literal

log = logging.getLogger(__name__)

# Keys of harness.metrics.compute_metrics kept in a row's "metrics" (status/message are row fields).
METRIC_NAMES = (
    "e1_rms", "e1_max", "e2_rms", "e2_max", "e2_plant_rms", "e2_plant_max", "deN_rms", "beta_min",
    "ya_max", "e1_final", "e2_final", "range_violation", "mujoco_warnings", "sim_time_reached",
    "wall_time", "realtime_factor",
)
LOWER_IS_WORSE = frozenset({"beta_min"})
# axis labels of the summary plots (units as in harness.metrics)
METRIC_LABELS = {
    "e1_rms": "e1_rms [m]", "e1_max": "e1_max [m]", "e2_rms": "e2_rms [m]", "e2_max": "e2_max [m]",
    "e2_plant_rms": "e2_plant_rms [m]", "e2_plant_max": "e2_plant_max [m]",
    "deN_rms": "deN_rms [mixed: m/s, 1/(m s)]", "beta_min": "beta_min [-] (41)", "ya_max": "ya_max [-] (29)",
    "e1_final": "e1_final [m]", "e2_final": "e2_final [m]", "range_violation": "range_violation [m or rad]",
    "mujoco_warnings": "mujoco_warnings [count]", "sim_time_reached": "sim_time_reached [s]",
    "wall_time": "wall_time [s]", "realtime_factor": "realtime_factor [x real time]",
}
DISTRIBUTIONS = {
    "uniform": ("low", "high"), "loguniform": ("low", "high"), "normal": ("mean", "std"),
    "integers": ("low", "high"),
}
DEFAULT_OUT_ROOT = Path("runs") / "sweeps"
RESULTS = "results.jsonl"
_PLANT_TABLES = (("plant", "master"), ("plant", "slave"))
_PARAM_RE = re.compile(r"^([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)(?:\[(\d+)\])?$")


# --- study file -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Factor:
    name: str
    param: str  # as written, e.g. "plant.slave.masses[0]"
    path: tuple[str, ...]  # ("plant", "slave", "masses")
    index: int | None  # 0 for "[0]"
    mode: str  # "scale" | "values"
    levels: tuple | None  # list factor: its levels; None for a random factor
    dist: dict | None  # random factor: {"random": kind, ...}

    @property
    def is_random(self) -> bool:
        return self.dist is not None


@dataclass(frozen=True)
class RecordSpec:
    worst: int
    by: str
    order: str  # "max" | "min": which end of the metric is worst


@dataclass(frozen=True)
class Study:
    name: str
    description: str
    scenario: Path | dict | None  # base scenario: file, inline table, or None = built-in paper
    set: tuple[str, ...]
    metrics: tuple[str, ...]
    record: RecordSpec | None
    factors: tuple[Factor, ...]
    mode: str  # "grid" | "random"
    n: int | None
    seed: int

    @property
    def scenario_source(self) -> Path | dict | None:
        return self.scenario  # None = load_scenario's built-in defaults (the paper scenario)


@dataclass(frozen=True)
class Case:
    case_id: str
    params: dict  # factor name -> level (scale factor or absolute value), JSON-able
    overrides: tuple[str, ...]  # scenario overrides of this case (after the study's `set`)
    scenario: Scenario


def _check_keys(table: Any, allowed: Sequence[str], where: str,
                elsewhere: dict[str, str] | None = None) -> None:
    """Unknown keys of a study table are an error naming them, the allowed ones and, per key, where it
    belongs (`elsewhere`: key -> table) or the closest allowed spelling."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: expected a table, got {table!r}")
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        hints = []
        for k in unknown:
            if elsewhere and k in elsewhere:
                hints.append(f"{k!r} belongs under {elsewhere[k]}")
            else:
                close = difflib.get_close_matches(str(k), list(allowed), n=1)
                if close:
                    hints.append(f"did you mean {close[0]!r} for {k!r}?")
        hint = f" ({'; '.join(hints)})" if hints else ""
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}{hint}")


def _is_real(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _canon(v) -> str:
    return json.dumps(v, sort_keys=True, separators=(",", ":"), default=str)


def _parse_dist(spec: dict, where: str) -> dict:
    kind = spec.get("random")
    if kind not in DISTRIBUTIONS:
        raise ConfigError(f"{where}: random = {kind!r}; expected one of {sorted(DISTRIBUTIONS)}")
    keys = DISTRIBUTIONS[kind]
    _check_keys(spec, ("random", *keys), where)
    missing = [k for k in keys if k not in spec]
    if missing or not all(_is_real(spec[k]) for k in keys):
        raise ConfigError(f"{where}: random = {kind!r} needs numbers {list(keys)}, got {spec!r}")
    a, b = (spec[k] for k in keys)
    if kind == "normal" and not b > 0:
        raise ConfigError(f"{where}: std must be > 0, got {b!r}")
    if kind in ("uniform", "loguniform") and not a < b:
        raise ConfigError(f"{where}: need low < high, got {spec!r}")
    if kind == "loguniform" and not a > 0:
        raise ConfigError(f"{where}: loguniform needs low > 0, got {a!r}")
    if kind == "integers" and not (isinstance(a, int) and isinstance(b, int) and a <= b):
        raise ConfigError(f"{where}: integers needs integer low <= high, got {spec!r}")
    return dict(spec)


def _parse_factor(i: int, t: Any) -> Factor:
    where = f"[[factor]] #{i + 1}"
    _check_keys(t, ("name", "param", "scale", "values"), where)
    param = t.get("param")
    if not isinstance(param, str):
        raise ConfigError(f"{where}: 'param' (a dotted Scenario path) is required")
    name = t.get("name", param)
    where = f"[[factor]] {name!r}"
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{where}: 'name' must be a non-empty string")
    m = _PARAM_RE.match(param)
    if not m:
        raise ConfigError(f"{where}: param = {param!r} is not a dotted path like 'plant.slave.masses[0]'")
    path = tuple(m.group(1).split("."))
    index = None if m.group(2) is None else int(m.group(2))
    if path[0] in ("master", "slave"):
        raise ConfigError(
            f"{where}: param = {param!r} is the controller's nominal model; a mismatch study varies "
            f"the plant: use 'plant.{param}'")
    if path == ("name",):
        raise ConfigError(f"{where}: the scenario name is not a parameter")
    modes = [k for k in ("scale", "values") if k in t]
    if len(modes) != 1:
        raise ConfigError(f"{where}: give exactly one of 'scale' (factors) or 'values' (absolute values)")
    mode = modes[0]
    spec = t[mode]
    if isinstance(spec, dict):
        return Factor(name, param, path, index, mode, None, _parse_dist(spec, f"{where}: {mode}"))
    if not isinstance(spec, list) or not spec:
        raise ConfigError(f"{where}: {mode} must be a non-empty list or a {{random = ...}} table")
    if mode == "scale" and not all(_is_real(v) for v in spec):
        raise ConfigError(f"{where}: scale = {spec!r}: every entry must be a number")
    keys = [_canon(v) for v in spec]
    if len(set(keys)) != len(keys):
        raise ConfigError(f"{where}: {mode} = {spec!r} has duplicate entries")
    return Factor(name, param, path, index, mode, tuple(spec), None)


def load_study(source: str | os.PathLike | dict, base_dir: str | os.PathLike | None = None) -> Study:
    """Parse and check a study (TOML file or the equivalent dict).  Structural errors raise
    `ConfigError` naming the table/factor; values are checked by `expand_cases`.
    `base_dir` resolves a relative `study.scenario` (default: the study file's folder, or cwd)."""
    if isinstance(source, dict):
        doc, stem = source, None
        base = Path(base_dir) if base_dir is not None else Path.cwd()
    else:
        path = Path(source)
        doc = read_toml(path, "study file")
        stem = path.stem
        base = Path(base_dir) if base_dir is not None else path.resolve().parent
    study_keys = ("name", "scenario", "set", "metrics", "record", "description")
    belongs = {k: "[study]" for k in study_keys if k != "scenario"}
    belongs.update({k: "[sampling]" for k in ("mode", "n", "seed")} | {"param": "[[factor]]"})
    _check_keys(doc, ("study", "factor", "sampling", "scenario"),
                "study file" if stem is None else f"study file {source}", belongs)
    st = doc.get("study", {})
    _check_keys(st, study_keys, "[study]")
    name = st.get("name", stem)
    if not isinstance(name, str) or not re.fullmatch(r"[\w.-]+", name):
        raise ConfigError(f"[study] name = {name!r}: required; letters, digits, '_', '-', '.' only")

    scenario: Path | dict | None = None
    if "scenario" in st and "scenario" in doc:
        raise ConfigError("give either [study] scenario (a file) or an inline [scenario] table, not both")
    if "scenario" in st:
        if not isinstance(st["scenario"], str):
            raise ConfigError(f"[study] scenario = {st['scenario']!r}: must be a path string")
        scenario = (base / st["scenario"]).resolve()
    elif "scenario" in doc:
        if not isinstance(doc["scenario"], dict):
            raise ConfigError("[scenario] must be a table (an inline base scenario)")
        scenario = doc["scenario"]

    sets = st.get("set", [])
    if not (isinstance(sets, list) and all(isinstance(s, str) for s in sets)):
        raise ConfigError(f"[study] set = {sets!r}: must be a list of 'key=value' strings")

    metrics = st.get("metrics", list(METRIC_NAMES))
    if not (isinstance(metrics, list) and metrics and all(isinstance(m, str) for m in metrics)):
        raise ConfigError(f"[study] metrics = {metrics!r}: must be a non-empty list of metric names")
    bad = [m for m in metrics if m not in METRIC_NAMES]
    if bad:
        raise ConfigError(f"[study] metrics: unknown {bad}; known: {list(METRIC_NAMES)}")

    record = None
    if "record" in st:
        r = st["record"]
        _check_keys(r, ("worst", "by", "order"), "[study] record")
        worst, by = r.get("worst", 1), r.get("by", "e2_rms")
        if not (isinstance(worst, int) and not isinstance(worst, bool) and worst >= 1):
            raise ConfigError(f"[study] record.worst = {worst!r}: must be an integer >= 1")
        if by not in metrics:
            raise ConfigError(f"[study] record.by = {by!r}: must be one of the collected metrics {metrics}")
        order = r.get("order", "min" if by in LOWER_IS_WORSE else "max")
        if order not in ("max", "min"):
            raise ConfigError(f"[study] record.order = {order!r}: 'max' or 'min'")
        record = RecordSpec(worst, by, order)

    ftables = doc.get("factor", [])
    if not isinstance(ftables, list) or not ftables:
        raise ConfigError("study file: at least one [[factor]] table is required")
    factors = tuple(_parse_factor(i, t) for i, t in enumerate(ftables))
    names = [f.name for f in factors]
    if len(set(names)) != len(names):
        raise ConfigError(f"[[factor]] names must be unique, got {names}")
    for a, b in itertools.combinations(factors, 2):
        if a.path == b.path and (a.index is None or b.index is None or a.index == b.index):
            raise ConfigError(f"[[factor]] {a.name!r} and {b.name!r} both set {a.param!r} / {b.param!r}")

    sp = doc.get("sampling", {})
    _check_keys(sp, ("mode", "n", "seed"), "[sampling]")
    mode, n, seed = sp.get("mode", "grid"), sp.get("n"), sp.get("seed", 0)
    if mode not in ("grid", "random"):
        raise ConfigError(f"[sampling] mode = {mode!r}: 'grid' or 'random'")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ConfigError(f"[sampling] seed = {seed!r}: must be an integer >= 0")
    needs_n = mode == "random" or any(f.is_random for f in factors)
    if needs_n and not (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
        raise ConfigError(f"[sampling] n = {n!r}: an integer >= 1 is required for random draws")
    if not needs_n and n is not None:
        raise ConfigError("[sampling] n is used only with mode = 'random' or random factors")
    description = st.get("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"[study] description = {description!r}: must be a string")
    return Study(name, description, scenario, tuple(sets), tuple(metrics), record, factors, mode, n, seed)


# --- case expansion ---------------------------------------------------------------------------------
def _clean(x: float) -> float:
    """Round to 12 significant digits: 0.35000000000000003 -> 0.35 (stable labels and ids)."""
    return float(f"{x:.12g}")


def _draws(study: Study, f: Factor, n: int) -> list:
    key = int.from_bytes(hashlib.sha256(f.name.encode()).digest()[:8], "little")
    rng = np.random.default_rng([study.seed, key])
    if f.levels is not None:  # list factor in random mode: uniform choice
        return [f.levels[i] for i in rng.integers(len(f.levels), size=n)]
    d = f.dist
    kind = d["random"]
    if kind == "uniform":
        x = rng.uniform(d["low"], d["high"], n)
    elif kind == "loguniform":
        x = np.exp(rng.uniform(math.log(d["low"]), math.log(d["high"]), n))
    elif kind == "normal":
        x = rng.normal(d["mean"], d["std"], n)
    else:
        return [int(v) for v in rng.integers(d["low"], d["high"] + 1, size=n)]
    return [_clean(float(v)) for v in x]


def _level_combinations(study: Study) -> list[tuple]:
    """One tuple of levels (in factor order) per case."""
    fs = study.factors
    if study.mode == "random":
        cols = [_draws(study, f, study.n) for f in fs]
        return list(zip(*cols, strict=True))
    grid = [f.levels if not f.is_random else (None,) for f in fs]
    rand = {i: _draws(study, f, study.n) for i, f in enumerate(fs) if f.is_random}
    out = []
    for point in itertools.product(*grid):
        for j in range(study.n if rand else 1):
            out.append(tuple(rand[i][j] if i in rand else v for i, v in enumerate(point)))
    return out


def _get(obj: Any, path: Sequence[str], base: Scenario, where: str) -> Any:
    """Field at `path`; an unset plant.master/plant.slave reads as the base plant model."""
    for i, p in enumerate(path):
        if not dataclasses.is_dataclass(obj) or p not in {f.name for f in dataclasses.fields(obj)}:
            owner = ".".join(path[:i]) or "Scenario"
            known = sorted(f.name for f in dataclasses.fields(obj)) if dataclasses.is_dataclass(obj) else []
            hint = f"; fields: {known}" if known else ""
            raise ConfigError(f"{where}: {owner} has no field {p!r}{hint}")
        obj = getattr(obj, p)
        if obj is None and tuple(path[: i + 1]) in _PLANT_TABLES:
            obj = base.plant_master if p == "master" else base.plant_slave
    if dataclasses.is_dataclass(obj):
        raise ConfigError(f"{where}: {'.'.join(path)!r} is a table; name one of its fields")
    return obj


def _pick(v: Any, index: int | None, where: str) -> Any:
    if index is None:
        return v
    if not isinstance(v, tuple | list) or not 0 <= index < len(v):
        raise ConfigError(f"{where}: index [{index}] out of range for value {v!r}")
    return v[index]


def _scaled(nominal: Any, s: float, where: str) -> Any:
    if isinstance(nominal, tuple | list):
        return [_scaled(v, s, where) for v in nominal]
    if not _is_real(nominal):
        raise ConfigError(f"{where}: cannot scale {nominal!r}; use 'values' for this parameter")
    x = nominal * s
    if isinstance(nominal, int):
        if abs(x - round(x)) > 1e-9:
            raise ConfigError(f"{where}: scale {s} of the integer {nominal} gives {x}, not an integer")
        return int(round(x))
    return _clean(float(x))


def _case_overrides(base: Scenario, factors: Sequence[Factor], levels: Sequence) -> list[str]:
    leaves: dict[tuple[str, ...], Any] = {}
    for f, level in zip(factors, levels, strict=True):
        where = f"[[factor]] {f.name!r} ({f.param})"
        current = leaves.get(f.path, _get(base, f.path, base, where))
        if f.mode == "scale":
            nominal_root = {("plant", "master"): base.master, ("plant", "slave"): base.slave}.get(f.path[:2])
            nominal = current if nominal_root is None else _get(nominal_root, f.path[2:], base, where)
            value = _scaled(_pick(nominal, f.index, where), level, where)
        else:
            value = level
        if f.index is not None:
            _pick(current, f.index, where)
            new = list(current)
            new[f.index] = value
            value = new
        elif isinstance(current, tuple) and _is_real(value) and all(_is_real(c) for c in current):
            value = [value] * len(current)  # a scalar for a vector field: every entry
        leaves[f.path] = value
    return [f"{'.'.join(path)}={toml_literal(value)}" for path, value in leaves.items()]


def scenario_id(scn: Scenario) -> str:
    """Short stable id of a resolved scenario (its name excluded)."""
    d = {k: v for k, v in scenario_to_dict(scn).items() if k != "name"}
    return hashlib.sha256(_canon(d).encode()).hexdigest()[:12]


def _in_context(e: ValueError, context: str) -> ConfigError:
    return e.with_context(context) if isinstance(e, ConfigError) else ConfigError(f"{context}: {e}")


def load_base(study: Study) -> Scenario:
    try:
        return load_scenario(study.scenario_source, list(study.set))
    except ValueError as e:  # ConfigError, or a model's ParameterError
        raise _in_context(e, f"study {study.name!r}: base scenario (with [study] set)") from None


def expand_cases(study: Study, base: Scenario | None = None) -> list[Case]:
    """All cases of the study, each validated by `load_scenario` (ConfigError naming the factor
    values on the first bad one), duplicates (same resolved scenario) removed."""
    base = load_base(study) if base is None else base
    cases: dict[str, Case] = {}
    for levels in _level_combinations(study):
        params = {f.name: jsonable(v) for f, v in zip(study.factors, levels, strict=True)}
        ovr = _case_overrides(base, study.factors, levels)
        try:
            scn = load_scenario(study.scenario_source, [*study.set, *ovr])
        except ValueError as e:
            raise _in_context(e, f"study {study.name!r}: case {params}") from None
        cid = scenario_id(scn)
        if cid not in cases:
            scn = dataclasses.replace(scn, name=f"{study.name}-{cid}")
            cases[cid] = Case(cid, params, tuple(ovr), scn)
        elif cases[cid].params != params:
            log.warning("study %s: case %s is the same scenario as %s; run once",
                        study.name, params, cases[cid].params)
    return list(cases.values())


# --- worker -----------------------------------------------------------------------------------------
def _error_result(e: BaseException) -> dict:
    return {"status": "error", "message": f"{type(e).__name__}: {e}",
            "traceback": "".join(traceback.format_exception(e))}


def run_case(case: dict) -> dict:
    """Worker: simulate one case and compute its metrics.  Never raises (an exception gives status
    "error" with the message and traceback); a diverged run keeps the Trajectory's status.

    case: {"case_id", "scenario": Scenario, "metrics": [names], "record": bool}.
    Returns {"case_id", "status", "message", "metrics", "wall_time", "traceback"} (+ "recording":
    the .rrd bytes when case["record"])."""
    t0 = time.perf_counter()
    out = {"case_id": case.get("case_id"), "metrics": {}, "traceback": ""}
    try:
        from harness.metrics import compute_metrics
        from harness.sim import simulate

        scn = case["scenario"]
        traj = simulate(scn, progress=False)
        metrics = compute_metrics(traj, scn)
        out.update(status=traj.status, message=traj.message,
                   metrics={k: jsonable(metrics.get(k)) for k in case["metrics"]})
        if case.get("record"):
            from harness.record import write_recording

            with tempfile.TemporaryDirectory(prefix="sweep-rec-") as tmp:
                path = Path(tmp) / f"{case.get('case_id')}.rrd"
                write_recording(traj, path)
                out["recording"] = path.read_bytes()
    except Exception as e:
        out.update(_error_result(e))
    out["wall_time"] = time.perf_counter() - t0
    return out


def _call(case_fn: Callable[[dict], dict], payload: dict) -> dict:
    """Runs in the worker: an exception raised by case_fn is the case's result, so that any exception
    a future raises in the parent comes from the executor itself."""
    try:
        return case_fn(payload)
    except Exception as e:
        return _error_result(e)


def _worker_init() -> None:
    # Ctrl-C reaches the whole process group: only the parent reacts (it cancels and stops us).
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# --- results table ----------------------------------------------------------------------------------
def read_results(path: str | os.PathLike) -> dict[str, dict]:
    """Rows of a results.jsonl by case id (first occurrence wins).  A last line without its newline
    (torn by a crash) is ignored; other unreadable lines are skipped with a warning."""
    path = Path(path)
    rows: dict[str, dict] = {}
    if not path.exists():
        return rows
    lines = path.read_bytes().split(b"\n")
    if lines[-1].strip():
        log.warning("%s: ignoring a torn last line (%d bytes)", path, len(lines[-1]))
    for no, line in enumerate(lines[:-1], 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError:
            row = None
        if not isinstance(row, dict) or not isinstance(row.get("case_id"), str):
            log.warning("%s:%d: unreadable row skipped", path, no)
            continue
        rows.setdefault(row["case_id"], row)
    return rows


class _ResultsWriter:
    """Appends rows to results.jsonl, one fsynced line each; cuts a torn tail off first."""

    def __init__(self, path: Path):
        if path.exists():
            data = path.read_bytes()
            keep = data.rfind(b"\n") + 1
            if keep != len(data):
                with open(path, "r+b") as fh:
                    fh.truncate(keep)
        self._fh = open(path, "ab")

    def append(self, row: dict) -> None:
        self._fh.write((json.dumps(row, allow_nan=False) + "\n").encode())
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


def _make_row(case: Case, result: dict) -> dict:
    return {
        "case_id": case.case_id,
        "params": case.params,
        "status": str(result.get("status", "error")),
        "message": str(result.get("message", "")),
        "metrics": jsonable(result.get("metrics") or {}),
        "wall_time": jsonable(result.get("wall_time")),
        "traceback": str(result.get("traceback", "")),
    }


# --- execution --------------------------------------------------------------------------------------
class SweepError(RuntimeError):
    """The executor failed (not a case): the sweep stops; finished rows are kept, a re-run resumes."""


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C / SIGTERM during a sweep; `.result` holds the partial SweepResult (rows are on disk)."""

    def __init__(self, result: SweepResult):
        super().__init__(f"sweep interrupted: {len(result.rows)} of {len(result.cases)} cases done")
        self.result = result


class _Runner:
    """An executor created on demand: a process pool (recreated after a worker died) or a Dask client."""

    def __init__(self, workers: int | None, scheduler: str | None):
        self.workers = max(1, workers or os.cpu_count() or 1)
        self.scheduler = scheduler
        self._ex: cf.Executor | None = None
        self._client = None

    @property
    def window(self) -> float:
        # Process pool: only `workers` cases in flight, so a dead worker implicates few cases.
        return math.inf if self.scheduler else self.workers

    def executor(self) -> cf.Executor:
        if self._ex is None:
            if self.scheduler:
                from distributed import Client

                try:
                    self._client = Client(self.scheduler)
                except (OSError, ValueError) as e:
                    raise ConfigError(f"scheduler = {self.scheduler!r}: cannot connect to the Dask "
                                      f"scheduler ({e})", path="scheduler") from None
                self._ex = self._client.get_executor(pure=False)
            else:
                self._ex = _process_pool(self.workers)
        return self._ex

    def close(self, cancel: bool = False) -> None:
        ex, self._ex = self._ex, None
        if ex is not None:
            if isinstance(ex, cf.ProcessPoolExecutor):
                _stop_pool(ex, cancel)
            else:
                ex.shutdown(wait=not cancel)
        if self._client is not None:
            self._client.close()
            self._client = None


def _process_pool(workers: int) -> cf.ProcessPoolExecutor:
    # "spawn": fresh interpreters (safe with the parent's threads), and unlike "forkserver" they see
    # the parent's current environment, not the one of whenever a fork server was started.
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_worker_init)


def _stop_pool(ex: cf.ProcessPoolExecutor, cancel: bool) -> None:
    if not cancel:
        ex.shutdown(wait=True)
        return
    if hasattr(ex, "terminate_workers"):  # Python >= 3.14
        ex.terminate_workers()
        return
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:  # running cases are lost (they re-run on resume); don't wait for them
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=10)


def _payload(case: Case, metrics: Sequence[str], record: bool) -> dict:
    return {"case_id": case.case_id, "scenario": case.scenario, "metrics": list(metrics), "record": record}


def _run_cases(runner: _Runner, case_fn: Callable, cases: Sequence[Case], metrics: Sequence[str],
               record: bool, on_result: Callable[[Case, dict], None]) -> None:
    """Run cases through the runner, calling on_result(case, result) in the parent as each finishes.
    An exception raised by case_fn counts as the case's result (status "error"); a dead process pool
    re-runs the cases that were in flight one by one to find the one that kills its worker."""
    queue = deque(cases)
    inflight: dict[cf.Future, Case] = {}
    try:
        while queue or inflight:
            ex = runner.executor()
            while queue and len(inflight) < runner.window:
                case = queue.popleft()
                try:
                    fut = ex.submit(_call, case_fn, _payload(case, metrics, record))
                except cf.BrokenExecutor:  # a worker died since the last wait: its futures say which
                    queue.appendleft(case)
                    break
                inflight[fut] = case
            if not inflight:  # broken before anything was in flight: nothing to blame, a fresh pool
                runner.close(cancel=True)
                continue
            done, _ = cf.wait(inflight, return_when=cf.FIRST_COMPLETED)
            if any(not f.cancelled() and isinstance(f.exception(), cf.BrokenExecutor) for f in done):
                cf.wait(inflight)  # a broken pool fails every future at once
                done = set(inflight)
            suspects = []
            for fut in done:
                case = inflight.pop(fut)
                if fut.cancelled():
                    raise RuntimeError(f"case {case.case_id} was cancelled by the executor "
                                       "(scheduler or workers lost?); run again to resume")
                exc = fut.exception()
                if exc is None:
                    on_result(case, fut.result())
                elif isinstance(exc, cf.BrokenExecutor):
                    suspects.append(case)
                elif type(exc).__name__ == "KilledWorker":  # Dask: this case killed its workers
                    on_result(case, _error_result(exc))
                else:
                    raise SweepError(f"the executor failed on case {case.case_id}: "
                                     f"{type(exc).__name__}: {exc}; re-run to resume") from exc
            if suspects:
                log.warning("a worker process died; re-running %d case(s) one at a time", len(suspects))
                runner.close(cancel=True)
                for case in suspects:
                    on_result(case, _isolated(case_fn, _payload(case, metrics, record)))
    finally:
        for fut in inflight:
            fut.cancel()


def _probe() -> int:
    return os.getpid()


def _isolated(case_fn: Callable, payload: dict) -> dict:
    """Run one case alone in a fresh 1-process pool whose worker has first run a no-op, so that a
    dead worker is this case's doing (else: SweepError, e.g. workers that cannot start)."""
    ex = _process_pool(1)
    try:
        try:
            ex.submit(_probe).result()
        except cf.BrokenExecutor:
            raise SweepError(
                "worker processes die before running any case (if run_sweep is called from a script, "
                "guard the call with `if __name__ == '__main__':`)") from None
        return ex.submit(_call, case_fn, payload).result()
    except cf.BrokenExecutor:
        return {"status": "error", "traceback": "", "message":
                "the worker process died while running this case (segfault, abort or out of memory)"}
    finally:
        _stop_pool(ex, cancel=True)


@dataclass
class SweepResult:
    study: Study
    out: Path
    cases: list[Case]
    rows: dict[str, dict]  # case id -> row, for this study's cases that have one
    ran: int = 0  # cases run by this call
    skipped: int = 0  # cases already in the table
    unfinished: int = 0  # cases that came back "interrupted" (not written; they re-run)
    recordings: list[Path] = dataclasses.field(default_factory=list)
    summary: list[Path] = dataclasses.field(default_factory=list)

    @property
    def complete(self) -> bool:
        return all(c.case_id in self.rows for c in self.cases)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.rows.values():
            out[r["status"]] = out.get(r["status"], 0) + 1
        return out


class _Lock:
    """Exclusive lock on the output folder: two sweeps must not append to the same table."""

    def __init__(self, out: Path):
        self._fh = open(out / ".lock", "w")
        try:
            import fcntl

            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # not POSIX: no lock
            pass
        except OSError:
            self._fh.close()
            raise ConfigError(f"{out} is in use by another sweep") from None

    def release(self) -> None:
        self._fh.close()


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


def _study_document(study: Study, base: Scenario) -> dict:
    st: dict[str, Any] = {"name": study.name, "set": list(study.set), "metrics": list(study.metrics)}
    if study.description:
        st["description"] = study.description
    if study.record:
        st["record"] = dataclasses.asdict(study.record)
    factors = []
    for f in study.factors:
        factors.append({"name": f.name, "param": f.param, f.mode: f.dist if f.is_random else list(f.levels)})
    sampling: dict[str, Any] = {"mode": study.mode, "seed": study.seed}
    if study.n is not None:
        sampling["n"] = study.n
    return {"study": st, "sampling": sampling, "factor": factors, "scenario": scenario_to_dict(base)}


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def run_sweep(study: str | os.PathLike | dict | Study, out: str | os.PathLike | None = None,
              workers: int | None = None, scheduler: str | None = None, progress: bool = True,
              case_fn: Callable[[dict], dict] = run_case,
              on_row: Callable[[dict], None] | None = None) -> SweepResult:
    """Run (or resume) a study.  Every case is built and validated before anything runs.

    out: output folder (default runs/sweeps/<name>); workers: process-pool size (default all
    cores); scheduler: Dask scheduler address (then `workers` is ignored); case_fn: the worker
    function (top-level, picklable; default `run_case`); on_row(row): called in the parent after
    each row is on disk.  Raises ConfigError for a bad study, SweepInterrupted on Ctrl-C/SIGTERM."""
    if not isinstance(study, Study):
        study = load_study(study)
    base = load_base(study)
    cases = expand_cases(study, base)
    if out is not None:
        out = prepare_out_dir(Path(out), "--out")
    else:
        out = prepare_out_dir(DEFAULT_OUT_ROOT / study.name, "sweep output folder (default)")
    lock = _Lock(out)
    in_main = threading.current_thread() is threading.main_thread()
    old_term = signal.signal(signal.SIGTERM, _raise_interrupt) if in_main else None
    runner = _Runner(workers, scheduler)
    writer = bar = None
    try:
        header = f"# Resolved study {study.name!r}, written by harness.sweep (re-runnable as a study file).\n"
        _write_atomic(out / "study.toml", (header + tomli_w.dumps(_study_document(study, base))).encode())
        table = out / RESULTS
        known = read_results(table)
        todo = [c for c in cases if c.case_id not in known]
        result = SweepResult(study, out, cases, {c.case_id: known[c.case_id] for c in cases
                                                 if c.case_id in known}, skipped=len(cases) - len(todo))
        extra = len(set(known) - {c.case_id for c in cases})
        log.info("study %s: %d cases, %d already done, %d to run%s", study.name, len(cases), result.skipped,
                 len(todo), f" ({extra} rows of other cases in the table)" if extra else "")
        writer = _ResultsWriter(table)
        bar = tqdm(total=len(cases), initial=result.skipped, desc=study.name, unit="case",
                   disable=not progress or not todo, file=sys.stderr)

        def on_result(case: Case, res: dict) -> None:
            row = _make_row(case, res)
            if row["status"] == "interrupted":  # the case did not finish: not a result, re-run it later
                result.unfinished += 1
                return
            writer.append(row)
            result.rows[case.case_id] = row
            result.ran += 1
            bar.update(1)
            bad = sum(r["status"] != "ok" for r in result.rows.values())
            if bad:
                bar.set_postfix_str(f"{bad} not ok", refresh=False)
            if on_row is not None:
                on_row(row)

        try:
            _run_cases(runner, case_fn, todo, study.metrics, False, on_result)
            bar.close()
            if study.record and result.complete:
                result.recordings = _record_worst(study, result, runner, case_fn)
            runner.close()
            result.summary = write_summary(study, cases, result.rows, out)
        except KeyboardInterrupt:
            runner.close(cancel=True)
            raise SweepInterrupted(result) from None
    finally:
        if bar is not None:
            bar.close()
        runner.close(cancel=True)  # no-op after a normal end; else stop the workers now
        if writer is not None:
            writer.close()
        if in_main:
            signal.signal(signal.SIGTERM, old_term)
        lock.release()
    return result


def _worst(study: Study, cases: Sequence[Case], rows: dict[str, dict]) -> list[Case]:
    spec = study.record

    def value(case):
        v = rows[case.case_id]["metrics"].get(spec.by)
        return v if _is_real(v) and rows[case.case_id]["status"] in ("ok", "diverged") else None

    ranked = [c for c in cases if value(c) is not None]
    ranked.sort(key=value, reverse=spec.order == "max")
    return ranked[: spec.worst]


def _record_worst(study: Study, result: SweepResult, runner: _Runner, case_fn: Callable) -> list[Path]:
    folder = result.out / "recordings"
    folder.mkdir(exist_ok=True)
    worst = _worst(study, result.cases, result.rows)
    todo = [c for c in worst if not (folder / f"{c.case_id}.rrd").exists()]
    written = [folder / f"{c.case_id}.rrd" for c in worst if c not in todo]

    def on_result(case: Case, res: dict) -> None:
        data = res.get("recording")
        if not isinstance(data, bytes | bytearray):
            log.warning("recording of case %s failed: %s", case.case_id, res.get("message", "no data"))
            return
        path = folder / f"{case.case_id}.rrd"
        _write_atomic(path, bytes(data))
        written.append(path)

    if todo:
        log.info("recording the %d worst case(s) by %s", len(todo), study.record.by)
        _run_cases(runner, case_fn, todo, study.metrics, True, on_result)
    return written


# --- summary ----------------------------------------------------------------------------------------
def _cell(v: Any) -> Any:
    return "" if v is None else (json.dumps(v) if isinstance(v, list | dict) else v)


def _label(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return json.dumps(v) if isinstance(v, list | dict) else str(v)


def _safe(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name)


def write_summary(study: Study, cases: Sequence[Case], rows: dict[str, dict],
                  out: str | os.PathLike) -> list[Path]:
    """summary.csv (one row per case of the study that has a result) and the plots; returns the paths."""
    out = Path(out)
    done = [rows[c.case_id] for c in cases if c.case_id in rows]
    names = [f.name for f in study.factors]
    path = out / "summary.csv"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["case_id", *names, "status", *study.metrics, "case_wall_time", "message"])
        for r in done:
            w.writerow([r["case_id"], *(_cell(r["params"].get(n)) for n in names), r["status"],
                        *(_cell(r["metrics"].get(m)) for m in study.metrics), _cell(r["wall_time"]),
                        r["message"]])
    return [path, *_plots(study, done, out)]


def _metric_array(rows: Sequence[dict], metric: str) -> np.ndarray:
    return np.array([v if _is_real(v := r["metrics"].get(metric)) else np.nan for r in rows], dtype=float)


def _nan_stats(values) -> tuple[float, float, float]:
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    return (np.nan, np.nan, np.nan) if a.size == 0 else (a.mean(), a.min(), a.max())


def _plots(study: Study, rows: Sequence[dict], out: Path) -> list[Path]:
    from matplotlib.figure import Figure

    metrics = [m for m in study.metrics if np.isfinite(_metric_array(rows, m)).any()]
    if not rows or not metrics:
        return []
    ncol = min(3, len(metrics))
    nrow = math.ceil(len(metrics) / ncol)
    paths = []

    def figure():
        fig = Figure(figsize=(4.6 * ncol, 3.4 * nrow), layout="constrained")
        return fig, fig.subplots(nrow, ncol, squeeze=False).ravel()

    def finish(fig, axes, name):
        for ax in axes[len(metrics):]:
            ax.set_visible(False)
        p = out / name
        fig.savefig(p, dpi=110)
        paths.append(p)

    sampled = study.mode == "random"
    grid_factors = [f for f in study.factors if not f.is_random and not sampled]
    bad = np.array([r["status"] != "ok" for r in rows])  # diverged / error: metrics of a partial run
    for f in study.factors:
        xs = [r["params"].get(f.name) for r in rows]
        if len({_canon(x) for x in xs}) < 2:
            continue
        fig, axes = figure()
        if f.is_random or sampled:  # scattered samples
            if all(_is_real(x) for x in xs):
                pos, ticks = np.array(xs, dtype=float), None
            else:
                keys = sorted({_canon(x) for x in xs})
                pos, ticks = np.array([keys.index(_canon(x)) for x in xs], dtype=float), keys
            for ax, m in zip(axes, metrics, strict=False):
                ax.scatter(pos[~bad], _metric_array(rows, m)[~bad], s=14)
                if ticks:
                    ax.set_xticks(range(len(ticks)), [_label(json.loads(k)) for k in ticks])
        else:
            levels = [json.loads(_canon(v)) for v in f.levels]
            keys = [_canon(v) for v in levels]
            x = np.array(levels, dtype=float) if all(_is_real(v) for v in levels) else np.arange(len(levels))
            pos = np.array([x[keys.index(_canon(v))] for v in xs], dtype=float)
            others = [g.name for g in grid_factors if g is not f]
            groups: dict[str, list[dict]] = {}
            for r in rows:
                key = ", ".join(f"{o}={_label(r['params'].get(o))}" for o in others)
                groups.setdefault(key, []).append(r)
            if len(groups) > 6:  # too many lines: one mean line with a min/max band
                groups = {"mean, min-max over the other factors": list(rows)}
            for ax, m in zip(axes, metrics, strict=False):
                for label, grp in groups.items():
                    vals = _metric_array(grp, m)
                    at = np.array([_canon(r["params"].get(f.name)) for r in grp])
                    stats = np.array([_nan_stats(vals[at == k]) for k in keys])
                    (line,) = ax.plot(x, stats[:, 0], marker="o", label=label or None)
                    if np.any(stats[:, 2] > stats[:, 1]):
                        ax.fill_between(x, stats[:, 1], stats[:, 2], alpha=0.2, color=line.get_color())
                if not all(_is_real(v) for v in levels):
                    ax.set_xticks(x, [_label(v) for v in levels])
        for ax, m in zip(axes, metrics, strict=False):
            if bad.any():
                ax.scatter(pos[bad], _metric_array(rows, m)[bad], marker="x", color="red", s=40, zorder=3,
                           label="diverged / error (partial run)")
            if ax is axes[0] and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize="x-small")
            ax.set_xlabel(f"{f.name} ({f.mode} of {f.param})")
            ax.set_ylabel(METRIC_LABELS.get(m, m))
            ax.grid(alpha=0.3)
        fig.suptitle(f"{study.name}: metrics vs {f.name}")
        finish(fig, axes, f"metric_vs_{_safe(f.name)}.png")

    multi = [f for f in grid_factors if len(f.levels) > 1]
    for fa, fb in itertools.combinations(multi, 2):
        ka = [_canon(v) for v in fa.levels]
        kb = [_canon(v) for v in fb.levels]
        fig, axes = figure()
        for ax, m in zip(axes, metrics, strict=False):
            cells: dict[tuple[int, int], list[float]] = {}
            flagged = set()
            for r, v, b_ in zip(rows, _metric_array(rows, m), bad, strict=True):
                a, b = _canon(r["params"].get(fa.name)), _canon(r["params"].get(fb.name))
                if a in ka and b in kb:
                    cells.setdefault((ka.index(a), kb.index(b)), []).append(v)
                    if b_:
                        flagged.add((ka.index(a), kb.index(b)))
            grid = np.full((len(kb), len(ka)), np.nan)
            for (i, j), vals in cells.items():
                grid[j, i] = _nan_stats(vals)[0]
            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis")
            fig.colorbar(im, ax=ax)
            for (j, i), v in np.ndenumerate(grid):
                text = ("-" if np.isnan(v) else f"{v:.3g}") + ("*" if (i, j) in flagged else "")
                ax.text(i, j, text, ha="center", va="center", fontsize=7, color="w")
            ax.set_xticks(range(len(ka)), [_label(v) for v in fa.levels])
            ax.set_yticks(range(len(kb)), [_label(v) for v in fb.levels])
            ax.set_xlabel(fa.name)
            ax.set_ylabel(fb.name)
            ax.set_title(METRIC_LABELS.get(m, m))
        more = " (mean over the other factors)" if len(study.factors) > 2 else ""
        star = "; * = some cases diverged or failed (partial runs)" if bad.any() else ""
        fig.suptitle(f"{study.name}: {fb.name} vs {fa.name}{more}{star}")
        finish(fig, axes, f"heatmap_{_safe(fa.name)}__{_safe(fb.name)}.png")
    return paths


# --- CLI entry --------------------------------------------------------------------------------------
EXIT_INTERRUPTED = 130  # as `teleop run` (harness.cli)


def main_sweep(study_path: str | os.PathLike, out: str | os.PathLike | None = None,
               workers: int | None = None, scheduler: str | None = None, progress: bool = True) -> int:
    """`teleop sweep`: 0 when every case has a row (diverged/error cases are data), 1 when cases are
    unfinished or the executor failed, 130 when interrupted (SIGINT/SIGTERM; re-run to resume).  A bad
    study or an unusable output folder raises ConfigError before anything runs."""
    try:
        res = run_sweep(study_path, out=out, workers=workers, scheduler=scheduler, progress=progress)
    except SweepError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except SweepInterrupted as e:
        r = e.result
        print(f"interrupted: {len(r.rows)} of {len(r.cases)} cases done, kept in {r.out / RESULTS}; "
              "run the same command again to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    counts = ", ".join(f"{n} {s}" for s, n in sorted(res.counts().items()))
    print(f"study {res.study.name}: {len(res.cases)} cases ({counts}); ran {res.ran}, "
          f"{res.skipped} already done -> {res.out}", file=sys.stderr)
    for p in res.recordings:
        print(f"recording: {p}", file=sys.stderr)
    if not res.complete:
        print(f"{res.unfinished} case(s) did not finish; run again to resume", file=sys.stderr)
        return 1
    return 0
