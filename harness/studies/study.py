"""Study files (`teleop sweep`, docs/reference/study.md): `load_study` checks the file (schema:
`harness.config.study`) and returns the resolved `Study`; running it: `harness.studies.sweep`."""

from __future__ import annotations

import itertools
import json
import math
import os
import re
from dataclasses import dataclass, fields, make_dataclass, replace
from pathlib import Path
from typing import Any

from harness.config.assets import shipped
from harness.config.errors import ConfigError
from harness.config.metrics import METRIC_UNITS
from harness.config.scenario import Scenario
from harness.config.schema import decode, did_you_mean, suggest
from harness.config.study import (  # noqa: F401 - DEFAULT_MAX_CASES, METRIC_NAMES re-exported
    DEFAULT_MAX_CASES,
    DISTRIBUTIONS,
    METRIC_NAMES,
    Factor,
    Record,
    SamplingTable,
    StudyFile,
    StudyTable,
)
from harness.config.textio import read_toml

LOWER_IS_WORSE = frozenset({"beta_min"})
METRIC_LABELS = {k: f"{k} [{u}]" for k, u in METRIC_UNITS.items()} | {
    "beta_min": "beta_min [-] (41)", "ya_max": "ya_max [-] (29)"}
DEFAULT_OUT_ROOT = Path("runs") / "sweeps"
DIST_TABLES = {k: make_dataclass(k, [("random", str), *spec.items()], frozen=True)
               for k, spec in DISTRIBUTIONS.items()}


def check_study_name(name: Any) -> str:
    """`name` if it is a folder name inside the output root (not only dots), else ConfigError."""
    if not isinstance(name, str) or not re.fullmatch(r"[\w.-]+", name) or not name.strip("."):
        raise ConfigError(f"[study] name = {name!r}: required; letters, digits, '_', '-', '.' only, and not "
                          "only dots (the name is a folder inside the output folder)")
    return name


# a checked study: the fields of [study] and [sampling] resolved (scenario: the base scenario's file, an
# inline table or None = the paper's; record: its order set), its factors, whether it may name Python
# controllers (--allow-code; a table: the caller's) and the folder its relative paths resolve against
Study = make_dataclass("Study", [(f.name, f.type) for f in (*fields(StudyTable), *fields(SamplingTable))]
                       + [("factors", tuple[Factor, ...]), ("allow_code", bool), ("base_dir", Path)],
                       frozen=True, namespace={"__module__": __name__})


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


def _check_factor(f: Factor) -> None:
    where, spec = f"[[factor]] {f.name!r}", getattr(f, f.mode)
    if f.path[0] in ("master", "slave"):
        raise ConfigError(f"{where}: param = {f.param!r} is the controller's nominal model; a mismatch study "
                          f"varies the plant: use 'plant.{f.param}'")
    if f.path == ("name",):
        raise ConfigError(f"{where}: the scenario name is not a parameter")
    if (f.scale is None) == (f.values is None):
        raise ConfigError(f"{where}: give exactly one of 'scale' (factors) or 'values' (absolute values)")
    if f.is_random:
        kind = spec.get("random")
        if not isinstance(kind, str) or kind not in DISTRIBUTIONS:  # (an unhashable value: one line too)
            hint = did_you_mean(suggest(kind, DISTRIBUTIONS)) if isinstance(kind, str) else ""
            raise ConfigError(f"{where}: {f.mode}: random = {kind!r}; {hint}expected one of "
                              f"{sorted(DISTRIBUTIONS)}")
        decode(spec, DIST_TABLES[kind], prefix=f"{where}: {f.mode}.")
        if kind != "normal" and (spec["high"] < spec["low"] if kind == "integers" else
                                 spec["high"] <= spec["low"]):
            raise ConfigError.field(f"{where}: {f.mode}.high", spec["high"],
                                    f"must be {'>=' if kind == 'integers' else '>'} low = {spec['low']!r}")
    elif not spec:
        raise ConfigError(f"{where}: {f.mode} must be a non-empty list or a {{random = ...}} table")
    elif len({canon(v) for v in spec}) != len(spec):
        raise ConfigError(f"{where}: {f.mode} = {spec!r} has duplicate entries")


def load_study(source: str | os.PathLike | dict, base_dir: str | os.PathLike | None = None, *,
               max_cases: int | None = None, allow_code: bool | None = None) -> Study:
    """The checked `Study` of a TOML file or table (values: `expand_cases`).  Raises ConfigError.
    base_dir: where relative paths resolve (default: the file's folder, or cwd); max_cases: replaces
    [sampling] max_cases; allow_code: may it name Python controllers (default: only a table may)."""
    if isinstance(source, dict):
        raw, stem, label = source, None, None
        base = Path(base_dir) if base_dir is not None else Path.cwd()
    else:
        path = shipped(source, "studies")
        raw, stem, label = read_toml(path, "study file"), path.stem, f"study file {source}"
        base = Path(base_dir) if base_dir is not None else path.resolve().parent
    try:
        f = decode(raw, StudyFile)
    except ConfigError as e:
        raise (e.with_context(label) if label else e) from None
    if not f.factor:
        raise ConfigError("study file: at least one [[factor]] table is required")
    st, sp, factors = f.study, f.sampling, f.factor
    if st.scenario is not None and f.scenario is not None:
        raise ConfigError("give either [study] scenario (a file) or an inline [scenario] table, not both")
    record = st.record
    if record is not None:
        if record.by not in st.metrics:
            raise ConfigError(f"[study] record.by = {record.by!r}: must be one of the collected metrics "
                              f"{list(st.metrics)}")
        record = replace(record, order=record.order or ("min" if record.by in LOWER_IS_WORSE else "max"))
    for factor in factors:
        _check_factor(factor)
    names = [f.name for f in factors]
    if len(set(names)) != len(names):
        raise ConfigError(f"[[factor]] names must be unique, got {names}")
    for a, b in itertools.combinations(factors, 2):
        if a.path == b.path and (a.index is None or b.index is None or a.index == b.index):
            raise ConfigError(f"[[factor]] {a.name!r} and {b.name!r} both set {a.param!r} / {b.param!r}")
    needs_n = sp.mode == "random" or any(f.is_random for f in factors)
    if needs_n and sp.n is None:
        raise ConfigError(f"[sampling] n = {sp.n!r}: an integer >= 1 is required for random draws")
    if not needs_n and sp.n is not None:
        raise ConfigError("[sampling] n is used only with mode = 'random' or random factors")
    resolved = {"name": check_study_name(st.name if st.name is not None else stem), "record": record,
                "scenario": (base / st.scenario).resolve() if st.scenario is not None else f.scenario,
                "max_cases": sp.max_cases if max_cases is None else check_max_cases(max_cases, "--max-cases"),
                "allow_code": isinstance(source, dict) if allow_code is None else bool(allow_code),
                "factors": factors, "base_dir": base.resolve()}
    study = Study(**{**vars(st), **vars(sp), **resolved})
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

