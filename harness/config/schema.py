"""The scenario schema: every field of the typed `Scenario` with its checker, and the primitive
checkers themselves.  A checker takes (dotted path, raw TOML value) and returns the converted value or
raises a one-line `ConfigError` naming the field, its value and the allowed range.
"""


from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import fields
from typing import Any

from controllers.params import Gains, MasterParams, ParameterError, SlaveParams, SubtaskSpec
from harness.config.checks import (
    KEY_RE,
    NONNEG,
    POSITIVE,
    Checker,
    Range,
    boolean,
    choice,
    integer,
    is_none_word,
    matrix,
    mjcf_path,
    name_check,
    num,
    num_list,
    optional,
    str_list,
    type_name,
    vec,
)
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

CONTROLLER_RE = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*|[^\x00-\x1f:][^\x00-\x1f]*:[A-Za-z_][A-Za-z0-9_]*)$")
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
    the loop layer (harness.config.controller.resolve_controller): config/ never imports controllers."""
    if isinstance(v, str):
        v = {"name": v}
    if not isinstance(v, Mapping):
        raise ConfigError.field(path, v, f"must be a table [controller] or a name (got {type_name(v)})")
    check_keys(v, path, ("name", "params", "step_timeout"))
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
    timeout = v.get("step_timeout", ControllerConfig.step_timeout)
    if is_none_word(timeout):
        timeout = None
    elif isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not 0 < timeout <= 86400:
        raise ConfigError.field(f"{path}.step_timeout", timeout,
                                'must be a number of seconds in (0, 86400] or "none" (no limit)')
    return ControllerConfig(name=name.strip(), params=out,
                            step_timeout=None if timeout is None else float(timeout))


# ---------------------------------------------------------------------------------------------
# table-valued top-level keys: [environment], [sensing.force], [operator] (contact issue)
# ---------------------------------------------------------------------------------------------
ENV_OBJECT: dict[str, Checker] = {
    "name": name_check, "kind": choice(ENV_KINDS), "position": vec(2), "normal": vec(2),
    "size": vec(2, POSITIVE), "angle": num(), "stiffness": num(POSITIVE), "damping_ratio": num(NONNEG),
}
FORCE_SENSING: dict[str, Checker] = {
    "mode": choice(FORCE_MODES), "noise_std": num(NONNEG),
    "cutoff": optional(num(POSITIVE), allow_false=True), "delay": num(NONNEG),
}


def _targets(path: str, v: Any) -> tuple[tuple[float, float, float], ...]:
    desc = "an array of [t, X, Z] triples (s, m, m) with strictly increasing t >= 0"
    if not isinstance(v, (list, tuple)):
        raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
    rows = tuple(vec(3)(path, r) for r in v)
    ts = [r[0] for r in rows]
    if any(t < 0 for t in ts) or any(b <= a for a, b in zip(ts, ts[1:], strict=False)):
        raise ConfigError.field(path, v, f"must be {desc}")
    return rows


OPERATOR: dict[str, Checker] = {
    "enabled": boolean, "mass": num(POSITIVE), "stiffness": num(NONNEG), "damping": num(NONNEG),
    "grip_stiffness": num(POSITIVE), "grip_damping": num(NONNEG), "targets": _targets,
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
        name_check(p, name)
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
    "name": name_check,
    "duration": num(Range(0.0, 3600.0, lo_open=True)),
    "control_dt": num(Range(0.0, 1.0, lo_open=True)),
    "snr_db": optional(num(Range(0.0, 200.0)), allow_false=True),
    "noise_model": choice(NOISE_MODELS),
    "seed": integer(0, 2**63 - 1),
    "transient": num(Range(0.0, 3600.0, hi_open=True)),
    "continuous_control": boolean,
    "interaction_forces": matrix(2, 2),
    "controller": _controller,
    "environment": _environment,
    "sensing": _sensing,
    "operator": _operator,
}
TABLE_KEYS = ("environment", "sensing", "operator")  # top-level keys whose value is a table

GAINS: dict[str, Checker] = {f.name: num(POSITIVE) for f in fields(Gains)}

MASTER: dict[str, Checker] = {
    "lengths": vec(2, POSITIVE),
    "masses": vec(2, POSITIVE),
    "damping": vec(2, NONNEG),
    "gravity": num(NONNEG),
}

SLAVE: dict[str, Checker] = {
    "rest_lengths": vec(3, POSITIVE),
    "masses": vec(3, POSITIVE),
    "bending_stiffness": vec(3, NONNEG),
    "extension_stiffness": vec(3, NONNEG),
    "extension_damping": vec(3, NONNEG),
    "bending_damping": vec(3, NONNEG),
    "slice_inertia": vec(3, NONNEG),
    "gravity": vec(2),
    "max_extension": num(Range(1.0, 100.0, lo_open=True)),
    "max_bend": num(Range(0.0, math.pi, lo_open=True)),
    "n_quad": integer(2, 32),
}

SUBTASK: dict[str, Checker] = {
    "kinds": str_list(("manipulability", "limits")),
    "weights": num_list(POSITIVE),
    "limit_power": integer(1, 10),
}

TRAJECTORY: dict[str, Checker] = {
    "center": vec(2),
    "amplitude": vec(2),
    "omega": num(),
}

INITIAL: dict[str, Checker] = {
    "master_offset": vec(2),
    "master_elbow": integer(-1, 1, allowed=(-1, 1)),
    "slave_q2": optional(vec(6)),
    "slave_curvature": num(),
}

PLANT: dict[str, Checker] = {
    "kind": choice(PLANTS),
    "actuation": choice(ACTUATIONS),
    "segments": integer(1, 64),
    "enforce_cc": boolean,
    "physics_dt": num(Range(0.0, 0.01, lo_open=True)),
    "integrator": choice(INTEGRATORS),
    "servo_frequency": num(Range(0.0, 1000.0, lo_open=True)),
    "servo_damping_ratio": num(POSITIVE),
    "servo_feedforward": boolean,
    "actuation_delay": num(NONNEG),
    "armature_fraction": num(NONNEG),
    "scene_xml": optional(mjcf_path),
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
    "elements_per_section": integer(2, 200),
    "dt": _auto_or(num(Range(0.0, 0.01, lo_open=True))),
    "shear_factor": num(Range(0.0, 1e6, lo_open=True)),
    "rotary_radius": num(Range(0.0, 1.0, lo_open=True)),
    "elastic_law": choice(ELASTIC_LAWS),
}


def _cosserat_table(path: str, v: Any) -> CosseratConfig:
    """The [plant.cosserat] table (missing keys: defaults); its own fields are checked one by one."""
    tbl = as_table(path, v)
    return build_section(CosseratConfig, read_fields(tbl, path, COSSERAT, CosseratConfig()), path)


PLANT["bending_viscosity"] = vec(3, NONNEG)  # N m^2 s per section
PLANT["extension_viscosity"] = vec(3, NONNEG)  # N s per section
PLANT["cosserat"] = _cosserat_table

FAULTS: dict[str, Checker] = {
    "e2_sign": integer(-1, 1, allowed=(-1, 1)),
    "null_space_scale": num(Range(0.0, 10.0)),
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
