"""Case expansion of a study: the levels of every factor (lists or seeded draws; grid or random sampling),
one resolved `Scenario` per case (base + `set` + one override per varied field), its id (a hash of it)."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from harness.config.controller import resolve_controller
from harness.config.errors import ConfigError
from harness.config.load import load_scenario, scenario_to_dict
from harness.config.scenario import Scenario
from harness.config.textio import jsonable, toml_literal
from harness.studies.study import Case, Factor, Study, canon, check_case_count, is_real

log = logging.getLogger(__name__)

PLANT_TABLES = (("plant", "master"), ("plant", "slave"))  # plant sub-tables defaulting to the nominal model


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
        named = [o for o in obj if getattr(o, "name", None) == p] if isinstance(obj, tuple) else []
        if named:  # named entries of a tuple, e.g. environment.objects.<name>
            obj = named[0]
            continue
        if not dataclasses.is_dataclass(obj) or p not in {f.name for f in dataclasses.fields(obj)}:
            owner = ".".join(path[:i]) or "Scenario"
            known = sorted(f.name for f in dataclasses.fields(obj)) if dataclasses.is_dataclass(obj) else []
            hint = f"; fields: {known}" if known else ""
            raise ConfigError(f"{where}: {owner} has no field {p!r}{hint}")
        obj = getattr(obj, p)
        if obj is None and tuple(path[: i + 1]) in PLANT_TABLES:
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
    if not is_real(nominal):
        raise ConfigError(f"{where}: cannot scale {nominal!r}; use 'values' for this parameter")
    x = nominal * s
    if isinstance(nominal, int):
        if abs(x - round(x)) > 1e-9:
            raise ConfigError(f"{where}: scale {s} of the integer {nominal} gives {x}, not an integer")
        return int(round(x))
    return _clean(float(x))


def _controller_leaf(base: Scenario, f: Factor, level: Any, where: str) -> Any:
    """Value of a `controller` (the name: the whole [controller] table is replaced, so the params start
    from the class defaults) or `controller.params.<key>` factor level."""
    if f.path == ("controller",) or f.path == ("controller", "name"):
        if f.mode != "values" or not isinstance(level, str):
            raise ConfigError(f"{where}: give the controllers as values = [\"paper\", \"dls_ik\", ...]")
        timeout = base.controller.step_timeout
        return {"name": level, "step_timeout": "none" if timeout is None else timeout}
    if len(f.path) != 3 or f.path[1] != "params":
        raise ConfigError(f"{where}: a controller factor is 'controller' or 'controller.params.<key>'")
    if f.mode == "values":
        return level
    nominal = base.controller.params.get(f.path[2])
    if nominal is None:
        raise ConfigError(f"{where}: scale needs controller.params.{f.path[2]} in the base scenario; "
                          "use values")
    return _scaled(_pick(nominal, f.index, where), level, where)


def _case_overrides(base: Scenario, factors: Sequence[Factor], levels: Sequence) -> list[str]:
    leaves: dict[tuple[str, ...], Any] = {}
    # a `controller` factor replaces the whole [controller] table: before any controller.params factor
    pairs = sorted(zip(factors, levels, strict=True), key=lambda fl: fl[0].path[:1] != ("controller",)
                   or len(fl[0].path) > 2)
    for f, level in pairs:
        where = f"[[factor]] {f.name!r} ({f.param})"
        if f.path[0] == "controller":
            path = ("controller",) if f.path[-1] == "name" else f.path
            leaves[path] = _controller_leaf(base, f, level, where)
            continue
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
        elif isinstance(current, tuple) and is_real(value) and all(is_real(c) for c in current):
            value = [value] * len(current)  # a scalar for a vector field: every entry
        leaves[f.path] = value
    return [f"{'.'.join(path)}={toml_literal(value)}" for path, value in leaves.items()]


def scenario_id(scn: Scenario) -> str:
    """Short stable id of a resolved scenario (its name excluded)."""
    d = {k: v for k, v in scenario_to_dict(scn).items() if k != "name"}
    return hashlib.sha256(canon(d).encode()).hexdigest()[:12]


def _load(study: Study, overrides: Sequence[str], context: str, check=None) -> Scenario:
    """The study's base scenario with `overrides`, then check(scenario) (returns a scenario); errors as a
    ConfigError in `context`.  Python controllers only if the study allows them (paths: its folder)."""
    try:
        scn = load_scenario(study.scenario, list(overrides), allow_code=study.allow_code,
                            code_dir=study.base_dir)
        return scn if check is None else check(scn)
    except ValueError as e:
        err = e.with_context(context) if isinstance(e, ConfigError) else ConfigError(f"{context}: {e}")
        raise err from None


def load_base(study: Study) -> Scenario:
    """The base scenario (with `set`), its plant checked too (harness.plant.validate_plant)."""
    from harness.plant import validate_plant

    def check(scn):
        validate_plant(scn)
        return scn

    return _load(study, study.set, f"study {study.name!r}: base scenario (with [study] set)", check)


def expand_cases(study: Study, base: Scenario | None = None) -> list[Case]:
    """All cases of the study, each validated by `load_scenario` (ConfigError naming the factor
    values on the first bad one), duplicates (same resolved scenario) removed."""
    check_case_count(study)  # before expanding anything
    base = load_base(study) if base is None else base
    cases: dict[str, Case] = {}
    for levels in _level_combinations(study):
        params = {f.name: jsonable(v) for f, v in zip(study.factors, levels, strict=True)}
        ovr = _case_overrides(base, study.factors, levels)
        scn = _load(study, [*study.set, *ovr], f"study {study.name!r}: case {params}", resolve_controller)
        cid = scenario_id(scn)
        if cid not in cases:
            scn = dataclasses.replace(scn, name=f"{study.name}-{cid}")
            cases[cid] = Case(cid, params, tuple(ovr), scn)
        elif cases[cid].params != params:
            log.warning("study %s: case %s is the same scenario as %s; run once",
                        study.name, params, cases[cid].params)
    return list(cases.values())
