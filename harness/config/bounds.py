"""Acceptance bounds on run metrics (`teleop check`).

A bounds file is TOML with one ``[bounds]`` table (and an optional top-level ``description``)::

    description = "paper scenario on the MuJoCo plant"
    [bounds]
    e1_rms_max = 1.0e-3        # m, RMS of |e1| after the transient must be <= this
    e1_max_max = 2.0e-3        # m, max of |e1| after the transient
    e2_rms_max = 1.0e-2        # m
    e2_max_max = 2.0e-2        # m
    e2_plant_rms_max = 1.0e-2  # m, against the MuJoCo tip site (optional)
    e2_plant_max_max = 2.0e-2  # m (optional)
    beta_min_min = 1.0e-3      # the minimum of beta must stay >= this
    no_mujoco_warnings = true  # mujoco_warnings must be 0
    status_ok = true           # status must be "ok" (default true)

Every key is optional; ``<metric>_max`` bounds a metric from above, ``<metric>_min`` from below.
Numeric limits must be finite numbers > 0.  A bound whose metric is missing (absent, None or NaN,
which `harness.loop.metrics` reports for e.g. e2_plant_* on the analytic plant or a run that stopped before
the transient) is a violation ("not measured"), as is an infinite or non-numeric measured value.

Metric names (from `harness.loop.metrics.compute_metrics`): e1_rms, e1_max, e2_rms, e2_max, e2_plant_rms,
e2_plant_max, beta_min, deN_rms, range_violation, the contact metrics (contact_force_peak,
contact_force_rms, penetration_max, contact_time, force_tracking_rms), mujoco_warnings (int), status (str).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from harness.config.assets import shipped
from harness.config.errors import ConfigError, short_repr
from harness.config.textio import read_toml

# bound key -> (metric, relation, unit, description)
NUMERIC_BOUNDS: dict[str, tuple[str, str, str, str]] = {
    "e1_rms_max": ("e1_rms", "max", "m", "RMS of the master tracking error |e1| after the transient"),
    "e1_max_max": ("e1_max", "max", "m", "max of |e1| after the transient"),
    "e2_rms_max": ("e2_rms", "max", "m", "RMS of the coordination error |e2| after the transient"),
    "e2_max_max": ("e2_max", "max", "m", "max of |e2| after the transient"),
    "e2_plant_rms_max": ("e2_plant_rms", "max", "m", "RMS of |x1 - MuJoCo tip site| after the transient"),
    "e2_plant_max_max": ("e2_plant_max", "max", "m", "max of |x1 - MuJoCo tip site| after the transient"),
    "beta_min_min": ("beta_min", "min", "", "minimum manipulability beta (41) must stay above"),
    "deN_rms_max": ("deN_rms", "max", "",
                    "RMS of the null-space velocity error |de_N| (23) after the transient"),
    "range_violation_max": ("range_violation", "max", "",
                            "largest excursion of section lengths (m) / bend angles (rad) "
                            "outside their range"),
    # contact scenarios (harness.loop.metrics.contact_metrics)
    "contact_force_peak_max": ("contact_force_peak", "max", "N",
                               "peak |true F2| (slave tip contact + constant)"),
    "contact_force_rms_max": ("contact_force_rms", "max", "N", "RMS |true F2| after the transient"),
    "contact_force_rms_min": ("contact_force_rms", "min", "N",
                              "RMS |true F2| after the transient (contact held)"),
    "penetration_max_max": ("penetration_max", "max", "m", "max penetration of the arm into an object"),
    "contact_time_min": ("contact_time", "min", "s", "time with any arm contact"),
    "force_tracking_rms_max": ("force_tracking_rms", "max", "N",
                               "RMS |F2 given to the law - true F2| after the transient"),
}
FLAG_BOUNDS: dict[str, str] = {
    "no_mujoco_warnings": "mujoco_warnings must be 0",
    "status_ok": 'status must be "ok"',
}


@dataclass(frozen=True)
class Bounds:
    """Acceptance limits; None = not checked."""

    e1_rms_max: float | None = None
    e1_max_max: float | None = None
    e2_rms_max: float | None = None
    e2_max_max: float | None = None
    e2_plant_rms_max: float | None = None
    e2_plant_max_max: float | None = None
    beta_min_min: float | None = None
    deN_rms_max: float | None = None
    range_violation_max: float | None = None
    contact_force_peak_max: float | None = None
    contact_force_rms_max: float | None = None
    contact_force_rms_min: float | None = None
    penetration_max_max: float | None = None
    contact_time_min: float | None = None
    force_tracking_rms_max: float | None = None
    no_mujoco_warnings: bool = False
    status_ok: bool = True
    description: str = ""


def _fmt(x: Any, unit: str = "") -> str:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        text = short_repr(x, 40)
    elif isinstance(x, int):
        text = str(x)
    elif x == 0 or (1e-3 <= abs(x) < 1e4):
        text = f"{x:.4f}"
    else:
        text = f"{x:.3e}"
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


def _err(path: str, value: Any, expected: str) -> ConfigError:
    return ConfigError.field(path, value, expected)


def bounds_from_dict(raw: Mapping, label: str | None = None) -> Bounds:
    """Validate a parsed bounds table (the whole file: {"bounds": {...}, "description": ...})."""
    try:
        return _bounds_from_dict(raw)
    except ConfigError as e:
        raise (e.with_context(label) if label else e) from None


def _bounds_from_dict(raw: Mapping) -> Bounds:
    if not isinstance(raw, Mapping):
        raise ConfigError(f"bounds file must be a table, got {short_repr(raw)}")
    top_allowed = ["bounds", "description"]
    for k in raw:
        if k not in top_allowed:
            close = difflib.get_close_matches(str(k), top_allowed, n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(f"unknown key {k!r}; {hint}allowed top-level keys: bounds, description",
                              path=str(k))
    if "bounds" not in raw:
        raise ConfigError("missing [bounds] table", path="bounds")
    table = raw["bounds"]
    if not isinstance(table, Mapping):
        raise _err("bounds", table, "must be a table [bounds]")
    kwargs: dict[str, Any] = {}
    desc = raw.get("description", "")
    if not isinstance(desc, str):
        raise _err("description", desc, "must be a string")
    kwargs["description"] = desc
    allowed = list(NUMERIC_BOUNDS) + list(FLAG_BOUNDS)
    for k, v in table.items():
        path = f"bounds.{k}"
        if k in NUMERIC_BOUNDS:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool)
            try:
                f = float(v) if ok else math.nan
            except OverflowError:
                f = math.nan
            if not (math.isfinite(f) and f > 0):
                unit = NUMERIC_BOUNDS[k][2]
                raise _err(path, v, f"must be a finite number > 0{' (' + unit + ')' if unit else ''}")
            kwargs[k] = f
        elif k in FLAG_BOUNDS:
            if not isinstance(v, bool):
                raise _err(path, v, "must be true or false")
            kwargs[k] = v
        else:
            close = difflib.get_close_matches(str(k), allowed, n=2)
            hint = f"did you mean {' or '.join(repr('bounds.' + c) for c in close)}? " if close else ""
            raise ConfigError(f"unknown key {path!r}; {hint}allowed keys: {', '.join(allowed)}", path=path)
    return Bounds(**kwargs)


def load_bounds(source: str | Path | Mapping) -> Bounds:
    """Read and validate a bounds TOML file (or an already-parsed table).  Raises ConfigError."""
    if isinstance(source, Mapping):
        return bounds_from_dict(source)
    path = shipped(source, "bounds")  # a shipped name (paper_mujoco) works from any folder
    raw = read_toml(path, "bounds file")
    return bounds_from_dict(raw, label=str(path))


def _measured(metrics: Mapping, name: str) -> Any:
    """metrics[name] as a plain Python value; None when absent, None or NaN (= not measured)."""
    v = metrics.get(name)
    if hasattr(v, "item") and callable(v.item):  # numpy scalar
        try:
            v = v.item()
        except (ValueError, TypeError):
            pass
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def check_bounds(metrics: Mapping[str, Any], bounds: Bounds) -> list[Violation]:
    """Every violated bound, in the order of the Bounds fields (empty list = all satisfied)."""
    out: list[Violation] = []
    for f in fields(bounds):
        key, limit = f.name, getattr(bounds, f.name)
        if key in NUMERIC_BOUNDS:
            if limit is None:
                continue
            name, rel, unit, _ = NUMERIC_BOUNDS[key]
            v = _measured(metrics, name)
            if v is None:
                out.append(Violation(name, None, limit, key, rel, unit))
                continue
            is_num = isinstance(v, (int, float)) and not isinstance(v, bool)
            good = is_num and math.isfinite(v) and (v <= limit if rel == "max" else v >= limit)
            if not good:
                out.append(Violation(name, v, limit, key, rel, unit))
        elif key == "no_mujoco_warnings" and limit:
            v = _measured(metrics, "mujoco_warnings")
            if v is None:
                out.append(Violation("mujoco_warnings", None, 0, key, "max"))
            elif not (isinstance(v, (int, float)) and not isinstance(v, bool) and v == 0):
                out.append(Violation("mujoco_warnings", v, 0, key, "max"))
        elif key == "status_ok" and limit:
            v = _measured(metrics, "status")
            if v is None:
                out.append(Violation("status", None, "ok", key, "eq"))
            elif v != "ok":
                out.append(Violation("status", v, "ok", key, "eq"))
    return out


__all__ = ["FLAG_BOUNDS", "NUMERIC_BOUNDS", "Bounds", "Violation", "check_bounds", "load_bounds"]
