"""The scenario schema: every field of the typed `Scenario` with its checker, and the primitive
checkers themselves.  A checker takes (dotted path, raw TOML value) and returns the converted value or
raises a one-line `ConfigError` naming the field, its value and the allowed range.
"""


from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

from controllers.params import Gains, MasterParams, ParameterError, SlaveParams, SubtaskSpec
from harness.config.errors import ConfigError, short_repr
from harness.config.scenario import (
    ACTUATIONS,
    ELASTIC_LAWS,
    ENV_KINDS,
    FORCE_MODES,
    INTEGRATORS,
    NOISE_MODELS,
    PLANTS,
    ControllerConfig,
    CosseratConfig,
    EnvironmentConfig,
    EnvObject,
    FaultConfig,
    ForceSensingConfig,
    InitialState,
    OperatorConfig,
    PlantConfig,
    SensingConfig,
    TrajectoryConfig,
)

NONE_WORDS = ("none",)
NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+=,@-]{0,99}$")
KEY_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")
BARE_WORD_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.+-]*$")

Checker = Callable[[str, Any], Any]


# ---------------------------------------------------------------------------------------------
# primitive checkers: (dotted path, raw value) -> converted value, or ConfigError
# ---------------------------------------------------------------------------------------------
def type_name(v: Any) -> str:
    if v is None:
        return "nothing"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int):
        return "an integer"
    if isinstance(v, float):
        return "a float"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, (list, tuple)):
        return "an array"
    if isinstance(v, Mapping):
        return "a table"
    return f"a {type(v).__name__}"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _fmt(x: float) -> str:
    if x == math.pi:
        return "pi"
    return f"{x:g}"


class _Range:
    """A real interval; `None` ends are unbounded."""

    def __init__(self, lo: float | None = None, hi: float | None = None,
                 lo_open: bool = False, hi_open: bool = False) -> None:
        self.lo, self.hi, self.lo_open, self.hi_open = lo, hi, lo_open, hi_open

    def __contains__(self, x: float) -> bool:
        if self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo):
            return False
        if self.hi is not None and (x >= self.hi if self.hi_open else x > self.hi):
            return False
        return True

    def describe(self) -> str:
        if self.lo is None and self.hi is None:
            return "finite"
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {_fmt(self.lo)}"
        if self.lo is None:
            return f"{'<' if self.hi_open else '<='} {_fmt(self.hi)}"
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"in {left}{_fmt(self.lo)}, {_fmt(self.hi)}{right}"


POSITIVE = _Range(0.0, None, lo_open=True)
NONNEG = _Range(0.0, None)
FINITE = _Range()


def _as_float(v: Any) -> float | None:
    """float(v) for a finite real number (not bool), else None."""
    if not _is_number(v):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def _num(rng: _Range = FINITE) -> Checker:
    desc = "a finite number" if rng.describe() == "finite" else f"a number {rng.describe()}"

    def check(path: str, v: Any) -> float:
        f = _as_float(v)
        if f is None:
            got = "" if _is_number(v) else f" (got {type_name(v)})"
            raise ConfigError.field(path, v, f"must be {desc}{got}")
        if f not in rng:
            raise ConfigError.field(path, v, f"must be {desc}")
        return f

    check.desc = desc  # type: ignore[attr-defined]
    return check


def _int(lo: int, hi: int, allowed: tuple[int, ...] | None = None) -> Checker:
    desc = (f"one of the integers {', '.join(map(str, allowed))}" if allowed
            else f"an integer in [{lo}, {hi}]")

    def check(path: str, v: Any) -> int:
        if not isinstance(v, int) or isinstance(v, bool):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if not lo <= v <= hi or (allowed and v not in allowed):
            raise ConfigError.field(path, v, f"must be {desc}")
        return int(v)

    return check


def _bool(path: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ConfigError.field(path, v, f"must be true or false (got {type_name(v)})")
    return v


def _choice(options: Iterable[str]) -> Checker:
    options = tuple(options)
    desc = "one of " + ", ".join(repr(o) for o in options)

    def check(path: str, v: Any) -> str:
        if not isinstance(v, str):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if v not in options:
            close = difflib.get_close_matches(v, options, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError.field(path, v, f"must be {desc}{hint}")
        return v

    return check


def _name(path: str, v: Any) -> str:
    if not isinstance(v, str) or not NAME_RE.match(v):
        raise ConfigError.field(
            path, v, "must be a string of 1-100 letters, digits or _ . + = , @ - (usable as a folder "
            "name; no spaces or slashes, not starting with '.' or '-')")
    return v


def _mjcf_path(path: str, v: Any) -> str:
    """An existing MJCF file (its content is checked by the plant: `harness.plant.validate_plant`)."""
    if not isinstance(v, str) or not v.strip():
        raise ConfigError.field(path, v, "must be the path of an MJCF scene file (string)")
    if not Path(v).is_file():
        raise ConfigError.field(path, v, "must be an existing MJCF file (relative paths: from the "
                                "current directory); file not found")
    return v


_mjcf_path.desc = "the path of an MJCF scene file"  # type: ignore[attr-defined]
_mjcf_path.keep_message = True  # type: ignore[attr-defined]


def _vec(n: int, rng: _Range = FINITE, unit: str = "numbers") -> Checker:
    each = "" if rng.describe() == "finite" else f", each {rng.describe()}"
    desc = f"an array of {n} finite {unit}{each}"

    def check(path: str, v: Any) -> tuple[float, ...]:
        if not isinstance(v, (list, tuple)):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if len(v) != n:
            raise ConfigError.field(path, v, f"must be {desc} (got {len(v)} entries)")
        out = []
        for i, x in enumerate(v):
            f = _as_float(x)
            if f is None or f not in rng:
                raise ConfigError.field(path, v, f"must be {desc} (entry {i} is {short_repr(x, 30)})")
            out.append(f)
        return tuple(out)

    check.desc = desc  # type: ignore[attr-defined]
    return check


def _matrix(rows: int, cols: int) -> Checker:
    row = _vec(cols)
    desc = f"an array of {rows} arrays of {cols} finite numbers"

    def check(path: str, v: Any) -> tuple[tuple[float, ...], ...]:
        if not isinstance(v, (list, tuple)) or len(v) != rows:
            raise ConfigError.field(path, v, f"must be {desc}")
        try:
            return tuple(row(path, r) for r in v)
        except ConfigError:
            raise ConfigError.field(path, v, f"must be {desc}") from None

    return check


def _str_list(options: Iterable[str]) -> Checker:
    options = tuple(options)
    desc = "an array of distinct strings from " + ", ".join(repr(o) for o in options)

    def check(path: str, v: Any) -> tuple[str, ...]:
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) for x in v):
            raise ConfigError.field(path, v, f"must be {desc}")
        bad = [x for x in v if x not in options]
        if bad or len(set(v)) != len(v):
            raise ConfigError.field(path, v, f"must be {desc}")
        return tuple(v)

    return check


def _num_list(rng: _Range) -> Checker:
    desc = f"an array of finite numbers, each {rng.describe()}"

    def check(path: str, v: Any) -> tuple[float, ...]:
        if not isinstance(v, (list, tuple)):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        return _vec(len(v), rng)(path, v)

    return check


def is_none_word(v: Any) -> bool:
    return isinstance(v, str) and v.strip().lower() in NONE_WORDS


def _optional(inner: Checker, allow_false: bool = False) -> Checker:
    def check(path: str, v: Any) -> Any:
        if is_none_word(v) or (allow_false and v is False):
            return None
        try:
            return inner(path, v)
        except ConfigError:
            if getattr(inner, "keep_message", False):
                raise
            alt = ', "none" or false' if allow_false else ' or "none"'
            raise ConfigError.field(path, v, f"must be {inner.desc}{alt} (got {type_name(v)})") from None

    return check


CONTROLLER_RE = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*|[^\s:]+:[A-Za-z_][A-Za-z0-9_]*)$")
CONTROLLER_DESC = ("a built-in controller name (see 'teleop controllers'), 'path/to/file.py:ClassName' or "
                   "'package.module:ClassName'")


def _param_value(path: str, v: Any, depth: int = 0) -> Any:
    """A controller parameter: a TOML boolean, integer, finite float, string or array of these."""
    if isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ConfigError.field(path, v, "must be finite")
        return v
    if isinstance(v, (list, tuple)) and depth < 3:
        return [_param_value(f"{path}[{i}]", x, depth + 1) for i, x in enumerate(v)]
    raise ConfigError.field(path, v, f"must be a boolean, number, string or array (got {type_name(v)})")


def _controller(path: str, v: Any) -> ControllerConfig:
    """[controller]: a table {name, params} or just the name.  The class and its params are checked by
    the loop layer (harness.loop.controllers.resolve_controller): config/ never imports controllers."""
    if isinstance(v, str):
        v = {"name": v}
    if not isinstance(v, Mapping):
        raise ConfigError.field(path, v, f"must be a table [controller] or a name (got {type_name(v)})")
    check_keys(v, path, ("name", "params"))
    name = v.get("name", ControllerConfig.name)
    if not isinstance(name, str) or not CONTROLLER_RE.match(name.strip()):
        raise ConfigError.field(f"{path}.name", name, f"must be {CONTROLLER_DESC}")
    params = v.get("params", {})
    if is_none_word(params):
        params = {}
    if not isinstance(params, Mapping):
        raise ConfigError.field(f"{path}.params", params, f"must be a table (got {type_name(params)})")
    out = {}
    for k, x in params.items():
        if not isinstance(k, str) or not KEY_RE.match(k):
            raise ConfigError.field(f"{path}.params", k, "keys must be names like 'gain'")
        out[k] = _param_value(f"{path}.params.{k}", x)
    return ControllerConfig(name=name.strip(), params=out)


# ---------------------------------------------------------------------------------------------
# table-valued top-level keys: [environment], [sensing.force], [operator] (contact issue)
# ---------------------------------------------------------------------------------------------
ENV_OBJECT: dict[str, Checker] = {
    "name": _name, "kind": _choice(ENV_KINDS), "position": _vec(2), "normal": _vec(2),
    "size": _vec(2, POSITIVE), "angle": _num(), "stiffness": _num(POSITIVE), "damping_ratio": _num(NONNEG),
}
FORCE_SENSING: dict[str, Checker] = {
    "mode": _choice(FORCE_MODES), "noise_std": _num(NONNEG),
    "cutoff": _optional(_num(POSITIVE), allow_false=True), "delay": _num(NONNEG),
}


def _targets(path: str, v: Any) -> tuple[tuple[float, float, float], ...]:
    desc = "an array of [t, X, Z] triples (s, m, m) with strictly increasing t >= 0"
    if not isinstance(v, (list, tuple)):
        raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
    rows = tuple(_vec(3)(path, r) for r in v)
    ts = [r[0] for r in rows]
    if any(t < 0 for t in ts) or any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
        raise ConfigError.field(path, v, f"must be {desc}")
    return rows


OPERATOR: dict[str, Checker] = {
    "enabled": _bool, "mass": _num(POSITIVE), "stiffness": _num(NONNEG), "damping": _num(NONNEG),
    "grip_stiffness": _num(POSITIVE), "grip_damping": _num(NONNEG), "targets": _targets,
}


def _environment(path: str, v: Any) -> EnvironmentConfig:
    """[environment] with [environment.objects.<name>] tables (named, so that a dotted override such as
    environment.objects.wall.stiffness=1e5 reaches one object)."""
    tbl = as_table(path, v)
    check_keys(tbl, path, ["objects"])
    objs = as_table(f"{path}.objects", tbl.get("objects", {}))
    out = []
    for name, ov in objs.items():
        p = f"{path}.objects.{name}"
        _name(p, name)
        spec = {k: c for k, c in ENV_OBJECT.items() if k != "name"}
        kw = read_fields(as_table(p, ov), p, spec, EnvObject())
        if kw["kind"] == "plane" and math.hypot(*kw["normal"]) < 1e-9:
            raise ConfigError.field(f"{p}.normal", list(kw["normal"]), "must be a non-zero vector")
        out.append(EnvObject(name=name, **kw))
    return EnvironmentConfig(objects=tuple(out))


def _sensing(path: str, v: Any) -> SensingConfig:
    tbl = as_table(path, v)
    check_keys(tbl, path, ["force"])
    p = f"{path}.force"
    return SensingConfig(force=ForceSensingConfig(**read_fields(as_table(p, tbl.get("force", {})), p,
                                                                FORCE_SENSING, ForceSensingConfig())))


def _operator(path: str, v: Any) -> OperatorConfig:
    return OperatorConfig(**read_fields(as_table(path, v), path, OPERATOR, OperatorConfig()))


# ---------------------------------------------------------------------------------------------
# schema: section -> {field: checker}; every dataclass field must appear (tests check this)
# ---------------------------------------------------------------------------------------------
TOP: dict[str, Checker] = {
    "name": _name,
    "duration": _num(_Range(0.0, 3600.0, lo_open=True)),
    "control_dt": _num(_Range(0.0, 1.0, lo_open=True)),
    "snr_db": _optional(_num(_Range(0.0, 200.0)), allow_false=True),
    "noise_model": _choice(NOISE_MODELS),
    "seed": _int(0, 2**63 - 1),
    "transient": _num(_Range(0.0, 3600.0, hi_open=True)),
    "continuous_control": _bool,
    "interaction_forces": _matrix(2, 2),
    "controller": _controller,
    "environment": _environment,
    "sensing": _sensing,
    "operator": _operator,
}
TABLE_KEYS = ("environment", "sensing", "operator")  # top-level keys whose value is a table

GAINS: dict[str, Checker] = {f.name: _num(POSITIVE) for f in fields(Gains)}

MASTER: dict[str, Checker] = {
    "lengths": _vec(2, POSITIVE),
    "masses": _vec(2, POSITIVE),
    "damping": _vec(2, NONNEG),
    "gravity": _num(NONNEG),
}

SLAVE: dict[str, Checker] = {
    "rest_lengths": _vec(3, POSITIVE),
    "masses": _vec(3, POSITIVE),
    "bending_stiffness": _vec(3, NONNEG),
    "extension_stiffness": _vec(3, NONNEG),
    "extension_damping": _vec(3, NONNEG),
    "bending_damping": _vec(3, NONNEG),
    "slice_inertia": _vec(3, NONNEG),
    "gravity": _vec(2),
    "max_extension": _num(_Range(1.0, 100.0, lo_open=True)),
    "max_bend": _num(_Range(0.0, math.pi, lo_open=True)),
    "n_quad": _int(2, 32),
}

SUBTASK: dict[str, Checker] = {
    "kinds": _str_list(("manipulability", "limits")),
    "weights": _num_list(POSITIVE),
    "limit_power": _int(1, 10),
}

TRAJECTORY: dict[str, Checker] = {
    "center": _vec(2),
    "amplitude": _vec(2),
    "omega": _num(),
}

INITIAL: dict[str, Checker] = {
    "master_offset": _vec(2),
    "master_elbow": _int(-1, 1, allowed=(-1, 1)),
    "slave_q2": _optional(_vec(6)),
    "slave_curvature": _num(),
}

PLANT: dict[str, Checker] = {
    "kind": _choice(PLANTS),
    "actuation": _choice(ACTUATIONS),
    "segments": _int(1, 64),
    "enforce_cc": _bool,
    "physics_dt": _num(_Range(0.0, 0.01, lo_open=True)),
    "integrator": _choice(INTEGRATORS),
    "servo_frequency": _num(_Range(0.0, 1000.0, lo_open=True)),
    "servo_damping_ratio": _num(POSITIVE),
    "servo_feedforward": _bool,
    "actuation_delay": _num(NONNEG),
    "armature_fraction": _num(NONNEG),
    "scene_xml": _optional(_mjcf_path),
}
def _auto_or(inner: Checker) -> Checker:
    """"auto" or a value accepted by `inner`."""

    def check(path: str, v: Any) -> Any:
        if isinstance(v, str) and v == "auto":
            return "auto"
        try:
            return inner(path, v)
        except ConfigError:
            raise ConfigError.field(path, v, f'must be "auto" or {inner.desc}') from None

    return check


COSSERAT: dict[str, Checker] = {
    "elements_per_section": _int(2, 200),
    "dt": _auto_or(_num(_Range(0.0, 0.01, lo_open=True))),
    "shear_factor": _num(_Range(0.0, 1e6, lo_open=True)),
    "rotary_radius": _num(_Range(0.0, 1.0, lo_open=True)),
    "elastic_law": _choice(ELASTIC_LAWS),
}


def _cosserat_table(path: str, v: Any) -> CosseratConfig:
    """The [plant.cosserat] table (missing keys: defaults); its own fields are checked one by one."""
    tbl = as_table(path, v)
    return build_section(CosseratConfig, read_fields(tbl, path, COSSERAT, CosseratConfig()), path)


PLANT["bending_viscosity"] = _vec(3, NONNEG)  # N m^2 s per section
PLANT["extension_viscosity"] = _vec(3, NONNEG)  # N s per section
PLANT["cosserat"] = _cosserat_table

FAULTS: dict[str, Checker] = {
    "e2_sign": _int(-1, 1, allowed=(-1, 1)),
    "null_space_scale": _num(_Range(0.0, 10.0)),
}
PLANT_MODELS = ("master", "slave")  # optional sub-tables of [plant]

SECTIONS: dict[str, tuple[type, dict[str, Checker]]] = {
    "gains": (Gains, GAINS),
    "master": (MasterParams, MASTER),
    "slave": (SlaveParams, SLAVE),
    "subtask": (SubtaskSpec, SUBTASK),
    "trajectory": (TrajectoryConfig, TRAJECTORY),
    "initial": (InitialState, INITIAL),
    "plant": (PlantConfig, PLANT),
    "faults": (FaultConfig, FAULTS),
}


def schema_paths() -> list[str]:
    """Every settable dotted key (used for suggestions and tests)."""
    out = list(TOP)
    out += [f"sensing.force.{k}" for k in FORCE_SENSING] + [f"operator.{k}" for k in OPERATOR]
    for sec, (_, spec) in SECTIONS.items():
        out += [f"{sec}.{k}" for k in spec]
    for sub, spec in (("master", MASTER), ("slave", SLAVE), ("cosserat", COSSERAT)):
        out.append(f"plant.{sub}")
        out += [f"plant.{sub}.{k}" for k in spec]
    return out


def _suggest(path: str, key: str, siblings: Iterable[str]) -> str:
    siblings = list(siblings)
    close = difflib.get_close_matches(key, siblings, n=3, cutoff=0.6)
    prefix = path.rsplit(".", 1)[0] + "." if "." in path else ""
    hints = [prefix + c for c in close]
    # the key may belong to another section (e.g. top-level `segments` -> `plant.segments`)
    hints += [p for p in schema_paths() if p.rsplit(".", 1)[-1] == key and p != path and p not in hints]
    allowed = ", ".join(siblings)
    did = f"did you mean {' or '.join(repr(h) for h in hints[:4])}? " if hints else ""
    return f"unknown key {path!r}; {did}allowed keys here: {allowed}"


def check_keys(table: Mapping, prefix: str, allowed: Iterable[str]) -> None:
    allowed = list(allowed)
    for k in table:
        if not isinstance(k, str):
            raise ConfigError(f"{prefix or 'scenario'}: key {short_repr(k)} is not a string", path=prefix)
        if k not in allowed:
            path = f"{prefix}.{k}" if prefix else k
            raise ConfigError(_suggest(path, k, allowed), path=path)


def as_table(path: str, v: Any) -> Mapping:
    if not isinstance(v, Mapping):
        raise ConfigError.field(path, v, f"must be a table [{path}] (got {type_name(v)})")
    return v


def read_fields(table: Mapping, prefix: str, spec: dict[str, Checker], defaults: Any) -> dict[str, Any]:
    """Validate `table` against `spec`; missing keys take `getattr(defaults, key)`."""
    check_keys(table, prefix, spec)
    out = {}
    for key, check in spec.items():
        out[key] = check(f"{prefix}.{key}" if prefix else key, table[key]) if key in table \
            else getattr(defaults, key)
    return out


def build_section(cls: type, kwargs: dict[str, Any], prefix: str) -> Any:
    """Construct a params dataclass, turning its ParameterError into a ConfigError with the path."""
    try:
        return cls(**kwargs)
    except ParameterError as e:
        msg = str(e)
        owner = msg.split(".", 1)[0]
        # the dataclass messages start with their own short owner ("master.lengths = ...")
        path_prefix = prefix.rsplit(".", 1)[0] + "." if "." in prefix else ""
        msg = path_prefix + msg if owner and prefix.endswith(owner) else f"{prefix}: {msg}"
        raise ConfigError(msg, path=prefix) from None
    except (TypeError, ValueError) as e:  # defensive: should be caught by the checkers above
        raise ConfigError(f"{prefix}: {e}", path=prefix) from None


# ---------------------------------------------------------------------------------------------
# cross-field checks
# ---------------------------------------------------------------------------------------------
