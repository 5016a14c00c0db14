"""Study files (`teleop sweep`): `load_study` checks the file (schema: `harness.config.study`) and returns
the resolved `Study`; the format and its semantics are in docs/reference/study.md.  Running, results and
summaries: `harness.studies.sweep`.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from harness.config.assets import shipped
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.config.schema import decode, did_you_mean, suggest, unknown_keys
from harness.config.study import (  # noqa: F401 - DEFAULT_MAX_CASES, METRIC_NAMES re-exported
    DEFAULT_MAX_CASES,
    DISTRIBUTIONS,
    METRIC_NAMES,
    METRIC_UNITS,
    PARAM_RE,
    FactorTable,
    StudyFile,
)
from harness.config.textio import read_toml

LOWER_IS_WORSE = frozenset({"beta_min"})
METRIC_LABELS = {k: f"{k} [{u}]" for k, u in METRIC_UNITS.items()} | {
    "beta_min": "beta_min [-] (41)", "ya_max": "ya_max [-] (29)"}
DEFAULT_OUT_ROOT = Path("runs") / "sweeps"


def check_study_name(name: Any) -> str:
    """`name` if it is a folder name inside the output root (not only dots), else ConfigError."""
    if not isinstance(name, str) or not re.fullmatch(r"[\w.-]+", name) or not name.strip("."):
        raise ConfigError(f"[study] name = {name!r}: required; letters, digits, '_', '-', '.' only, and not "
                          "only dots (the name is a folder inside the output folder)")
    return name


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
    max_cases: int = 10000  # DEFAULT_MAX_CASES
    allow_code: bool = False  # the study may name Python controllers (--allow-code; a dict: the caller's)
    base_dir: Path | None = None  # the study file's folder: its relative paths resolve against it


@dataclass(frozen=True)
class Case:
    case_id: str
    params: dict  # factor name -> level (scale factor or absolute value), JSON-able
    overrides: tuple[str, ...]  # scenario overrides of this case (after the study's `set`)
    scenario: Scenario


def is_real(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def canon(v) -> str:
    return json.dumps(v, sort_keys=True, separators=(",", ":"), default=str)


def _parse_dist(spec: dict, where: str) -> dict:
    kind = spec.get("random")
    if not isinstance(kind, str) or kind not in DISTRIBUTIONS:  # (an unhashable value: one line too)
        hint = did_you_mean(suggest(kind, DISTRIBUTIONS)) if isinstance(kind, str) else ""
        raise ConfigError(f"{where}: random = {kind!r}; {hint}expected one of {sorted(DISTRIBUTIONS)}")
    keys = DISTRIBUTIONS[kind]
    bad = {k: v for k, v in spec.items() if k not in ("random", *keys)}
    if bad:
        raise unknown_keys(f"{where}.", bad, ("random", *keys))
    missing = [k for k in keys if k not in spec]
    if missing or not all(is_real(spec[k]) for k in keys):
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


def _parse_factor(t: FactorTable) -> Factor:
    name = t.name if t.name is not None else t.param
    where = f"[[factor]] {name!r}"
    m = PARAM_RE.match(t.param)
    path = tuple(m.group(1).split("."))
    index = None if m.group(2) is None else int(m.group(2))
    if path[0] in ("master", "slave"):
        raise ConfigError(
            f"{where}: param = {t.param!r} is the controller's nominal model; a mismatch study varies "
            f"the plant: use 'plant.{t.param}'")
    if path == ("name",):
        raise ConfigError(f"{where}: the scenario name is not a parameter")
    modes = [k for k in ("scale", "values") if getattr(t, k) is not None]
    if len(modes) != 1:
        raise ConfigError(f"{where}: give exactly one of 'scale' (factors) or 'values' (absolute values)")
    mode = modes[0]
    spec = getattr(t, mode)
    if isinstance(spec, dict):
        return Factor(name, t.param, path, index, mode, None, _parse_dist(spec, f"{where}: {mode}"))
    if not spec:
        raise ConfigError(f"{where}: {mode} must be a non-empty list or a {{random = ...}} table")
    keys = [canon(v) for v in spec]
    if len(set(keys)) != len(keys):
        raise ConfigError(f"{where}: {mode} = {spec!r} has duplicate entries")
    return Factor(name, t.param, path, index, mode, tuple(spec), None)


def load_study(source: str | os.PathLike | dict, base_dir: str | os.PathLike | None = None, *,
               max_cases: int | None = None, allow_code: bool | None = None) -> Study:
    """The checked `Study` of a TOML file or table (values: `expand_cases`).  Raises ConfigError.
    base_dir: where relative paths resolve (default: the file's folder, or cwd); max_cases: replaces
    [sampling] max_cases; allow_code: may it name Python controllers (default: only a table may)."""
    if isinstance(source, dict):
        doc_, stem, label = source, None, None
        base = Path(base_dir) if base_dir is not None else Path.cwd()
    else:
        path = shipped(source, "studies")
        doc_, stem, label = read_toml(path, "study file"), path.stem, f"study file {source}"
        base = Path(base_dir) if base_dir is not None else path.resolve().parent
    try:
        f = decode(doc_, StudyFile)
    except ConfigError as e:
        raise (e.with_context(label) if label else e) from None
    if not f.factor:
        raise ConfigError("study file: at least one [[factor]] table is required")
    st, sp = f.study, f.sampling
    name = check_study_name(st.name if st.name is not None else stem)
    if st.scenario is not None and f.scenario is not None:
        raise ConfigError("give either [study] scenario (a file) or an inline [scenario] table, not both")
    scenario = (base / st.scenario).resolve() if st.scenario is not None else f.scenario
    metrics = list(st.metrics)
    record = None
    if st.record is not None:
        r = st.record
        if r.by not in metrics:
            raise ConfigError(f"[study] record.by = {r.by!r}: must be one of the collected metrics {metrics}")
        record = RecordSpec(r.worst, r.by, r.order or ("min" if r.by in LOWER_IS_WORSE else "max"))
    factors = tuple(_parse_factor(t) for t in f.factor)
    names = [f.name for f in factors]
    if len(set(names)) != len(names):
        raise ConfigError(f"[[factor]] names must be unique, got {names}")
    for a, b in itertools.combinations(factors, 2):
        if a.path == b.path and (a.index is None or b.index is None or a.index == b.index):
            raise ConfigError(f"[[factor]] {a.name!r} and {b.name!r} both set {a.param!r} / {b.param!r}")
    max_cases = sp.max_cases if max_cases is None else check_max_cases(max_cases, "--max-cases")
    needs_n = sp.mode == "random" or any(f.is_random for f in factors)
    if needs_n and sp.n is None:
        raise ConfigError(f"[sampling] n = {sp.n!r}: an integer >= 1 is required for random draws")
    if not needs_n and sp.n is not None:
        raise ConfigError("[sampling] n is used only with mode = 'random' or random factors")
    if allow_code is None:
        allow_code = isinstance(source, dict)
    study = Study(name, st.description, scenario, tuple(st.set), tuple(metrics), record, factors, sp.mode,
                  sp.n, sp.seed, max_cases, bool(allow_code), base.resolve())
    check_case_count(study)
    return study


def check_max_cases(v: Any, where: str) -> int:
    if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
        raise ConfigError(f"{where} = {v!r}: must be an integer >= 1")
    return v


def check_case_count(study: Study) -> None:
    """ConfigError if the study has more than `study.max_cases` cases (counted without expanding it)."""
    if study.mode == "random":
        count = int(study.n)
    else:
        count = math.prod(len(f.levels) for f in study.factors if not f.is_random)
        count *= study.n if any(f.is_random for f in study.factors) else 1
    if count > study.max_cases:
        raise ConfigError(f"study {study.name!r}: {count} cases, more than the limit of {study.max_cases} "
                          "([sampling] max_cases or --max-cases raise it)", path="[sampling] max_cases")

