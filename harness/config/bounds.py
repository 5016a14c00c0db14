"""Acceptance bounds on run metrics (`teleop check`): a [bounds] table of ``<metric>_max`` / ``<metric>_min``
limits and flags; a bounded metric not measured (absent, None, NaN) or not finite violates its bound."""

import contextlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from harness.config.assets import shipped
from harness.config.errors import ConfigError, short_repr
from harness.config.metrics import value_unit
from harness.config.schema import decode, doc, num
from harness.config.textio import read_toml


class _Limit(str):
    """The description of a bound field `<metric>_max` (measured <= limit) or `<metric>_min` (measured >=
    limit); `_limits` makes it the field's type."""


def _limits(cls: type) -> type:
    """Each `_Limit` annotation of `cls` as an optional number > 0 whose description starts with the unit
    of the field's metric (`METRIC_UNITS`)."""
    for name, desc in cls.__annotations__.items():
        if isinstance(desc, _Limit):
            unit = value_unit(name[:-4])
            cls.__annotations__[name] = doc(num("", gt=0.0) | None, f"{unit + ', ' if unit else ''}{desc}")
    return cls


@dataclass(frozen=True)
@_limits
class Bounds:
    """Acceptance limits; None = not checked."""

    e1_rms_max: _Limit("RMS of the master tracking error |e1| after the transient") = None
    e1_max_max: _Limit("max of |e1| after the transient") = None
    e2_rms_max: _Limit("RMS of the coordination error |e2| after the transient") = None
    e2_max_max: _Limit("max of |e2| after the transient") = None
    e2_plant_rms_max: _Limit("RMS of |x1 - MuJoCo tip site| after the transient") = None
    e2_plant_max_max: _Limit("max of |x1 - MuJoCo tip site| after the transient") = None
    beta_min_min: _Limit("minimum manipulability beta (41) must stay above") = None
    deN_rms_max: _Limit("RMS of the null-space velocity error |de_N| (23) after the transient") = None
    range_violation_max: _Limit("largest excursion of section lengths (m) / bend angles (rad) outside "
                                "their range") = None
    contact_force_peak_max: _Limit("peak |true F2| (slave tip contact + constant)") = None
    contact_force_rms_max: _Limit("RMS |true F2| after the transient") = None
    contact_force_rms_min: _Limit("RMS |true F2| after the transient (contact held)") = None
    penetration_max_max: _Limit("max penetration of the arm into an object") = None
    contact_time_min: _Limit("time with any arm contact") = None
    force_tracking_rms_max: _Limit("RMS |F2 given to the law - true F2| after the transient") = None
    no_mujoco_warnings: doc(bool, "mujoco_warnings must be 0") = False
    status_ok: doc(bool, 'status must be "ok"') = True


@dataclass(frozen=True)
class BoundsFile:
    bounds: doc(Bounds, "the acceptance limits")
    description: doc(str, "free text") = ""


FLAGS = {"no_mujoco_warnings": "mujoco_warnings", "status_ok": "status"}  # flag -> metric it checks


def limit_of(name: str) -> tuple[str, str, str]:
    """(metric, relation "max"/"min", unit written after its values) of a numeric bound field."""
    return name[:-4], name[-3:], value_unit(name[:-4])


def _fmt(x: Any, unit: str = "") -> str:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        text = short_repr(x, 40)
    elif isinstance(x, int):
        text = str(x)
    else:
        text = f"{x:.4f}" if x == 0 or 1e-3 <= abs(x) < 1e4 else f"{x:.3e}"
    return f"{text} {unit}" if unit else text


@dataclass(frozen=True)
class Violation:
    """One failed bound.  `measured` is None when the metric was not measured."""

    name: str  # metric name, e.g. "e2_rms"
    measured: Any
    limit: Any
    bound: str = ""  # bound key, e.g. "e2_rms_max"
    relation: str = "max"  # "max" (measured <= limit) | "min" (measured >= limit) | "eq"
    unit: str = ""

    def __str__(self) -> str:
        lim = _fmt(self.limit, self.unit)
        if self.measured is None:
            return f"{self.name} not measured (bound {self.bound or self.name} = {lim})"
        if self.relation == "eq":
            return f"{self.name} = {_fmt(self.measured)}, required {_fmt(self.limit)}"
        meas = _fmt(self.measured, self.unit)
        if not isinstance(self.measured, (int, float)) or isinstance(self.measured, bool):
            return f"{self.name} = {meas} is not a number (limit {lim})"
        if not math.isfinite(self.measured):
            return f"{self.name} = {meas} is not finite (limit {lim})"
        verb = "exceeds limit" if self.relation == "max" else "is below limit"
        return f"{self.name} = {meas} {verb} {lim}"


def bounds_from_dict(raw: Mapping, label: str | None = None) -> Bounds:
    """The `Bounds` of a parsed bounds file ({"bounds": {...}, "description": ...})."""
    try:
        return decode(raw, BoundsFile).bounds
    except ConfigError as e:
        raise (e.with_context(label) if label else e) from None


def load_bounds(source: str | Path | Mapping) -> Bounds:
    """The `Bounds` of a bounds TOML file or parsed table.  Raises ConfigError."""
    if isinstance(source, Mapping):
        return bounds_from_dict(source)
    path = shipped(source, "bounds")  # a shipped name (paper_mujoco) works from any folder
    return bounds_from_dict(read_toml(path, "bounds file"), label=str(path))


def _measured(metrics: Mapping, name: str) -> Any:
    """metrics[name] as a plain Python value; None when absent, None or NaN (= not measured)."""
    v = metrics.get(name)
    if hasattr(v, "item") and callable(v.item):  # numpy scalar
        with contextlib.suppress(ValueError, TypeError):
            v = v.item()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def check_bounds(metrics: Mapping[str, Any], bounds: Bounds) -> list[Violation]:
    """Every violated bound, in the order of the Bounds fields (empty list = all satisfied)."""
    out: list[Violation] = []
    for f in fields(bounds):
        key, limit = f.name, getattr(bounds, f.name)
        if limit is None or limit is False:
            continue
        if key in FLAGS:  # a count of MuJoCo warnings <= 0, status == "ok"
            name, unit = FLAGS[key], ""
            rel, limit = ("max", 0) if name == "mujoco_warnings" else ("eq", "ok")
        else:
            name, rel, unit = limit_of(key)
        v = _measured(metrics, name)
        is_num = isinstance(v, (int, float)) and not isinstance(v, bool)
        if not (v == limit if rel == "eq" else
                is_num and math.isfinite(v) and (v <= limit if rel == "max" else v >= limit)):
            out.append(Violation(name, v, limit, key, rel, unit))
    return out


__all__ = ["FLAGS", "Bounds", "BoundsFile", "Violation", "check_bounds", "limit_of", "load_bounds"]
