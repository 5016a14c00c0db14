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

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from harness.config.assets import shipped
from harness.config.errors import ConfigError, short_repr
from harness.config.schema import decode, doc, info, num, unknown_keys
from harness.config.textio import read_toml


def _limit(unit: str, desc: str) -> Any:
    """A bound `<metric>_max` (measured <= limit) or `<metric>_min` (measured >= limit)."""
    return doc(num("", gt=0.0) | None, f"{unit + ', ' if unit else ''}{desc}", unit=unit)


@dataclass(frozen=True)
class Bounds:
    """Acceptance limits; None = not checked."""

    e1_rms_max: _limit("m", "RMS of the master tracking error |e1| after the transient") = None
    e1_max_max: _limit("m", "max of |e1| after the transient") = None
    e2_rms_max: _limit("m", "RMS of the coordination error |e2| after the transient") = None
    e2_max_max: _limit("m", "max of |e2| after the transient") = None
    e2_plant_rms_max: _limit("m", "RMS of |x1 - MuJoCo tip site| after the transient") = None
    e2_plant_max_max: _limit("m", "max of |x1 - MuJoCo tip site| after the transient") = None
    beta_min_min: _limit("", "minimum manipulability beta (41) must stay above") = None
    deN_rms_max: _limit("", "RMS of the null-space velocity error |de_N| (23) after the transient") = None
    range_violation_max: _limit("", "largest excursion of section lengths (m) / bend angles (rad) outside "
                                "their range") = None
    contact_force_peak_max: _limit("N", "peak |true F2| (slave tip contact + constant)") = None
    contact_force_rms_max: _limit("N", "RMS |true F2| after the transient") = None
    contact_force_rms_min: _limit("N", "RMS |true F2| after the transient (contact held)") = None
    penetration_max_max: _limit("m", "max penetration of the arm into an object") = None
    contact_time_min: _limit("s", "time with any arm contact") = None
    force_tracking_rms_max: _limit("N", "RMS |F2 given to the law - true F2| after the transient") = None
    no_mujoco_warnings: doc(bool, "mujoco_warnings must be 0") = False
    status_ok: doc(bool, 'status must be "ok"') = True
    description: doc(str, "free text (top-level key of the file)") = ""


FLAGS = {"no_mujoco_warnings": "mujoco_warnings", "status_ok": "status"}  # flag -> metric it checks


def limit_of(name: str) -> tuple[str, str, str]:
    """(metric, relation "max"/"min", unit) of a numeric bound field."""
    unit = next(f.type.extra.get("unit", "") for f in info(Bounds).fields if f.name == name)
    return name[:-4], name[-3:], unit


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


def bounds_from_dict(raw: Mapping, label: str | None = None) -> Bounds:
    """Validate a parsed bounds table (the whole file: {"bounds": {...}, "description": ...})."""
    try:
        if not isinstance(raw, Mapping):
            raise ConfigError(f"bounds file must be a table, got {short_repr(raw)}")
        bad = {k: v for k, v in raw.items() if k not in ("bounds", "description")}
        if bad:
            raise unknown_keys("", bad, ("bounds", "description"))
        if "bounds" not in raw:
            raise ConfigError("missing [bounds] table", path="bounds")
        table, desc = raw["bounds"], raw.get("description", "")
        if not isinstance(desc, str):
            raise ConfigError.field("description", desc, "must be a string")
        if isinstance(table, Mapping) and "description" in table:
            allowed = [f.name for f in fields(Bounds)][:-1]
            raise unknown_keys("bounds.", {"description": table["description"]}, allowed)
        if isinstance(table, Mapping):
            table = {**table, "description": desc}
        return decode(table, Bounds, prefix="bounds.")
    except ConfigError as e:
        raise (e.with_context(label) if label else e) from None


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
        if key in FLAGS:
            name = FLAGS[key]
            want, rel = (0, "max") if name == "mujoco_warnings" else ("ok", "eq")
            v = _measured(metrics, name)
            is_num = isinstance(v, (int, float)) and not isinstance(v, bool)
            good = v == want and (name == "status" or is_num)
            if limit and not good:
                out.append(Violation(name, v, want, key, rel))
        elif key != "description" and limit is not None:
            name, rel, unit = limit_of(key)
            v = _measured(metrics, name)
            is_num = isinstance(v, (int, float)) and not isinstance(v, bool)
            within = is_num and math.isfinite(v) and (v <= limit if rel == "max" else v >= limit)
            if v is None or not within:
                out.append(Violation(name, v, limit, key, rel, unit))
    return out


__all__ = ["FLAGS", "Bounds", "Violation", "check_bounds", "limit_of", "load_bounds"]
