"""Scenario TOML <-> `Scenario`: defaults (docs/reference/scenario.md), `--set key=value` overrides,
cross-field checks, dumping.  Every error is a one-line `ConfigError`."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from controllers.params import SubtaskSpec
from harness.config.assets import shipped
from harness.config.errors import ConfigError, short_repr
from harness.config.scenario import KEY_RE, NAME_RE, EnvironmentConfig, Scenario, TrajectoryConfig
from harness.config.schema import decode, did_you_mean, info, suggest, type_name
from harness.config.textio import MAX_DEPTH, loads_toml, read_toml, toml_literal, write_atomic

BARE_WORD = r"^[A-Za-z_][A-Za-z0-9_.+-]*$"
REACH_MARGIN = 1e-3  # m, the desired trajectory must stay this far inside the master workspace annulus
MULTIPLE_RTOL = 1e-9  # relative tolerance for "integer multiple of a time step"
MAX_SUBSTEPS = 100_000  # control_dt / physics_dt
MAX_STEPS = 100_000_000  # duration / control_dt


def _is_multiple(x: float, step: float) -> tuple[bool, float]:
    ratio = x / step
    return math.isfinite(ratio) and abs(ratio - round(ratio)) <= MULTIPLE_RTOL * max(abs(ratio), 1.0), ratio


def trajectory_radius_range(traj: TrajectoryConfig, duration: float) -> tuple[float, float]:
    """min and max of |x_d(t)| over t in [0, duration] (the whole ellipse if one period fits)."""
    c, a, w = np.asarray(traj.center), np.asarray(traj.amplitude), traj.omega
    span = abs(w) * duration
    if span >= 2 * math.pi:
        theta = np.linspace(0.0, 2 * math.pi, 6300)
    else:
        n = int(min(max(math.ceil(span / 1e-3) + 2, 2), 6300))
        theta = np.linspace(0.0, span, n) * (1.0 if w >= 0 else -1.0)
    with np.errstate(all="ignore"):
        r = np.hypot(c[0] + a[0] * np.sin(theta), c[1] + a[1] * np.cos(theta))
    return (float(r.min()), float(r.max())) if np.all(np.isfinite(r)) else (0.0, math.inf)


def _check_reach(scn: Scenario) -> None:
    tr = scn.trajectory
    rmin, rmax = trajectory_radius_range(tr, scn.duration)
    off = scn.initial.master_offset
    x0 = (tr.center[0] + off[0], tr.center[1] + tr.amplitude[1] + off[1])  # x_d(0) + offset
    r0 = math.hypot(*x0)
    for label, m in (("nominal master (master.lengths)", scn.master),
                     ("plant master (plant.master.lengths)", scn.plant_master)):
        l1, l2 = m.lengths
        lo, hi = abs(l1 - l2) + REACH_MARGIN, l1 + l2 - REACH_MARGIN
        if not (lo <= rmin and rmax <= hi):
            raise ConfigError(
                f"trajectory (center = {list(tr.center)}, amplitude = {list(tr.amplitude)}): "
                f"x_d(t) = center + amplitude*(sin wt, cos wt) has |x_d| in [{rmin:.6g}, {rmax:.6g}] m, "
                f"outside the reachable annulus [{lo:.6g}, {hi:.6g}] m of the {label} with lengths "
                f"{list(m.lengths)} (|l1-l2| + {REACH_MARGIN:g} <= |x_d| <= l1 + l2 - {REACH_MARGIN:g})",
                path="trajectory")
        if not lo <= r0 <= hi:
            raise ConfigError(
                f"initial.master_offset = {list(scn.initial.master_offset)}: the initial master tip "
                f"x_d(0) + offset = [{x0[0]:.6g}, {x0[1]:.6g}] (|x| = {r0:.6g} m) is outside the reachable "
                f"annulus [{lo:.6g}, {hi:.6g}] m of the {label}", path="initial.master_offset")
    for label, s in (("nominal slave (slave)", scn.slave), ("plant slave (plant.slave)", scn.plant_slave)):
        reach = s.max_extension * sum(s.rest_lengths)
        if rmax > reach - REACH_MARGIN:
            raise ConfigError(
                f"trajectory (center = {list(tr.center)}, amplitude = {list(tr.amplitude)}): |x_d| reaches "
                f"{rmax:.6g} m, beyond what the fully extended {label} can reach "
                f"(max_extension * sum(rest_lengths) - {REACH_MARGIN:g} = {reach - REACH_MARGIN:.6g} m)",
                path="trajectory")


def _need(ok: bool, path: str, value: Any, expected: str) -> None:
    if not ok:
        raise ConfigError.field(path, value, expected)


def _cross_checks(scn: Scenario) -> None:
    p, dt, fs = scn.plant, scn.control_dt, scn.sensing.force
    _need(p.scene_xml is None or Path(p.scene_xml).is_file(), "plant.scene_xml", p.scene_xml,
          "must be an existing MJCF file (relative paths: from the current directory); file not found")
    _need(scn.transient < scn.duration, "transient", scn.transient,
          f"must be in [0, duration) = [0, {scn.duration:g}) s (set transient = 0 for short runs)")
    _need(dt <= scn.duration, "control_dt", dt, f"must be <= duration = {scn.duration:g} s")
    _need(scn.duration / dt <= MAX_STEPS, "control_dt", dt,
          f"gives duration / control_dt > {MAX_STEPS:g} control steps")
    ok, ratio = _is_multiple(dt, p.physics_dt)
    _need(ok and round(ratio) >= 1, "control_dt", dt, "must be an integer multiple (>= 1) of "
          f"plant.physics_dt = {p.physics_dt:g} s (ratio {ratio:.12g}, relative tolerance {MULTIPLE_RTOL:g})")
    _need(round(ratio) <= MAX_SUBSTEPS, "plant.physics_dt", p.physics_dt,
          f"gives control_dt / physics_dt = {ratio:.6g} > {MAX_SUBSTEPS} substeps")
    ok, ratio = _is_multiple(p.actuation_delay, dt)
    _need(ok, "plant.actuation_delay", p.actuation_delay,
          f"must be >= 0 and an integer multiple of control_dt = {dt:g} s (ratio {ratio:.12g})")
    _need(p.actuation_delay < scn.duration, "plant.actuation_delay", p.actuation_delay,
          f"must be < duration = {scn.duration:g} s")
    if scn.continuous_control:
        _need(p.kind == "analytic", "continuous_control", True,
              f"requires plant.kind = 'analytic' (got {p.kind!r})")
        _need(p.actuation_delay == 0, "continuous_control", True, "evaluates the law in every RK4 stage: "
              f"requires plant.actuation_delay = 0 (got {p.actuation_delay:g} s)")
    _need(abs(scn.trajectory.omega) * dt < math.pi, "trajectory.omega", scn.trajectory.omega,
          f"must satisfy |omega| < pi / control_dt = {math.pi / dt:.6g} rad/s")
    ps, q2 = scn.plant_slave, scn.initial.slave_q2
    lo, hi = ps.length_range
    for i in range(3 if q2 is not None else 0):
        d, k = q2[i], q2[3 + i]
        _need(lo[i] <= d <= hi[i], "initial.slave_q2", list(q2), f"section length d{i + 1} = {d:g} m must be "
              f"in [L0, max_extension*L0] = [{lo[i]:g}, {hi[i]:g}] m of the plant slave")
        _need(abs(k * d) <= ps.max_bend, "initial.slave_q2", list(q2), f"bend |k{i + 1} d{i + 1}| = "
              f"{abs(k * d):g} rad exceeds the plant slave max_bend = {ps.max_bend:g} rad")
    ok, ratio = _is_multiple(fs.delay, dt)
    _need(ok and fs.delay < scn.duration, "sensing.force.delay", fs.delay, "must be >= 0, < duration and an "
          f"integer multiple of control_dt = {dt:g} s (ratio {ratio:.12g})")
    if fs.cutoff is not None:
        _need(fs.cutoff * scn.duration * 2.0 * math.pi > 1.0, "sensing.force.cutoff", fs.cutoff,
              "is slower than the run: the filter time constant 1/(2 pi cutoff) must be < duration = "
              f"{scn.duration:g} s")
        _need(fs.cutoff < 0.5 / dt, "sensing.force.cutoff", fs.cutoff,
              f"must be < the control Nyquist frequency 1/(2 control_dt) = {0.5 / dt:g} Hz")
    needs = [("environment.objects", bool(scn.environment.objects), ("mujoco", "cosserat")),
             ("operator.enabled", scn.operator.enabled, ("mujoco",)),
             ("sensing.force.mode", fs.mode == "sensed", ("mujoco",))]
    for key, used, plants in needs:
        if used and p.kind not in plants:
            kinds = " or ".join(map(repr, plants))
            raise ConfigError(f"{key}: requires plant.kind = {kinds} (got {p.kind!r})", path=key)
    _check_reach(scn)
    if q2 is None:
        _check_auto_slave_start(scn)


def _check_auto_slave_start(scn: Scenario) -> None:
    """`initial.slave_q2 = none`: three equal sections of curvature k (one arc, tip height sin(3 d k) / k)
    must reach the master's initial tip height Z0 for some common section length d."""
    ps, k = scn.plant_slave, scn.initial.slave_curvature
    tr, off = scn.trajectory, scn.initial.master_offset
    z0 = tr.center[1] + tr.amplitude[1] + off[1]
    lo, hi = ps.length_range
    d_lo, d_hi = float(lo.max()), float(hi.min())
    if abs(k) * d_hi > ps.max_bend:
        raise ConfigError.field(
            "initial.slave_curvature", k,
            f"|k| * max section length = {abs(k) * d_hi:g} rad exceeds the plant slave max_bend = "
            f"{ps.max_bend:g} rad")
    d = np.linspace(d_lo, d_hi, 2001) if d_hi >= d_lo else np.array([])
    z = 3.0 * d if k == 0 else np.sin(3.0 * d * k) / k
    if not (z.size and z.min() - 1e-9 <= z0 <= z.max() + 1e-9):
        zr = f"[{z.min():.6g}, {z.max():.6g}]" if z.size else "empty (no common section length)"
        raise ConfigError(
            f"trajectory.center = {list(tr.center)}: with initial.slave_q2 = none the slave starts with "
            f"three equal sections of curvature initial.slave_curvature under the master tip (Z0 = "
            f"{z0:.6g} m), but their tip height range over the plant slave's section lengths "
            f"[{d_lo:.6g}, {d_hi:.6g}] m is {zr} m; move the trajectory or give initial.slave_q2 explicitly",
            path="trajectory.center")


def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b.c=value' -> (['a', 'b', 'c'], parsed TOML value).  Bare words become strings."""
    if not isinstance(text, str) or "=" not in text:
        raise ConfigError(f"override {short_repr(text)}: expected key=value (e.g. plant.segments=16)")
    key, _, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    parts = key.split(".")
    if not key or not all(re.match(KEY_RE, p) for p in parts):
        raise ConfigError(f"override {text!r}: {key!r} is not a dotted key like plant.segments")
    if not raw:
        raise ConfigError(f"override {text!r}: missing value after '='")
    try:
        value = loads_toml(f"v = {raw}", f"override {short_repr(text, 60)}")["v"]
    except tomllib.TOMLDecodeError as e:
        if re.match(BARE_WORD, raw):
            value = raw
        else:
            raise ConfigError(f"override {text!r}: invalid TOML value {raw!r} ({e})") from None
    return parts, value


def _apply_override(raw: dict, text: str) -> str:
    parts, value = parse_override(text)
    if parts[:2] == ["environment", "objects"] and len(parts) > 3:  # a field of an existing object
        objects = raw.get("environment", {}).get("objects", {}) if isinstance(raw.get("environment"), dict) \
            else {}
        names = list(objects) if isinstance(objects, dict) else []
        if parts[2] not in names:
            where = ".".join(parts[:3])
            raise ConfigError(f"override {text!r}: {where}: no such object; "
                              f"{did_you_mean('environment.objects.' + n for n in suggest(parts[2], names))}"
                              f"objects: {', '.join(names) or 'none'} (a new object is set as a whole table, "
                              f"environment.objects.{parts[2]}={{kind=\"box\", ...}})", path=where)
    node = raw
    for i, p in enumerate(parts[:-1]):
        child = node.get(p)
        if child is None or (isinstance(child, str) and child.strip().lower() == "none"):
            child = node[p] = {}
        elif not isinstance(child, dict):
            where = ".".join(parts[: i + 1])
            raise ConfigError(f"override {text!r}: {where} is not a table (it is {short_repr(child)})",
                              path=where)
        node = child
    node[parts[-1]] = value
    return ".".join(parts)


def _plain_copy(obj: Any, depth: int = 0) -> Any:
    """Deep copy of a user table (tuples -> lists) within the nesting limit of files."""
    if depth >= MAX_DEPTH and isinstance(obj, (Mapping, list, tuple)):
        raise ConfigError(f"scenario table: nested deeper than {MAX_DEPTH} levels of tables/arrays")
    if isinstance(obj, Mapping):
        return {k: _plain_copy(v, depth + 1) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain_copy(v, depth + 1) for v in obj]
    return obj


def file_reference(name: str) -> tuple[str, str] | None:
    """(path, class) of a 'path/to/file.py:Class' reference, None for anything else."""
    where, sep, attr = name.rpartition(":")
    return (where, attr) if sep and (where.endswith(".py") or "/" in where or "\\" in where) else None


def _rebase_controller(raw: dict, base: str | Path | None) -> None:
    """A relative controller file path in `raw` made relative to `base` (the naming file's folder)."""
    table = raw["controller"] if isinstance(raw.get("controller"), dict) else raw
    key = "name" if table is not raw else "controller"
    name = table.get(key)
    ref = file_reference(name.strip()) if isinstance(name, str) and base is not None else None
    if ref is not None and not Path(ref[0]).is_absolute():
        table[key] = f"{Path(base) / ref[0]}:{ref[1]}"


def load_scenario(source: str | Path | Mapping | None = None, overrides: Iterable[str] = (), *,
                  labels: Iterable[str | None] | None = None, allow_code: bool | None = None,
                  code_dir: str | Path | None = None) -> Scenario:
    """The validated `Scenario` of a TOML file, a parsed table or None (defaults), after the `key=value`
    overrides in order.  Raises `ConfigError`.

    labels: how each override is named in errors (e.g. "--segments 100"; default "override 'k=v'").
    allow_code: None = a Python controller is refused only when the scenario file names it; True =
    allowed; False = always refused.  code_dir: where relative controller files of a table or of the
    overrides resolve (default: the current folder)."""
    raw, label, default_name = {}, None, None  # label: the file's path in messages
    if isinstance(source, Mapping):
        raw = _plain_copy(source)
    elif source is not None:
        if not isinstance(source, (str, Path)):
            raise ConfigError(f"scenario source must be a path or a table, got {type_name(source)}")
        path = shipped(source, "scenarios")  # a shipped name (paper) works from any folder
        raw, label = read_toml(path, "scenario file"), str(path)
        default_name = path.stem if re.match(NAME_RE, path.stem) else None
    from_file = label is not None and "controller" in raw  # the scenario file names the controller
    _rebase_controller(raw, Path(label).resolve().parent if label is not None else code_dir)
    overrides = [overrides] if isinstance(overrides, str) else list(overrides or ())
    applied: list[tuple[str, str]] = []
    for text, lab in zip(overrides, [*(labels or ()), *[None] * len(overrides)], strict=False):
        try:
            key = _apply_override(raw, text)
        except ConfigError as e:
            raise (e.with_context(lab) if lab else e) from None
        applied.append((key, lab or f"override {text!r}"))
        if key in ("controller", "controller.name"):
            from_file = False
            _rebase_controller(raw, code_dir)
    try:
        table = _prepare(raw, default_name)
        scn = decode(table, Scenario)
        if "transient" not in table and scn.duration <= Scenario.transient:
            scn = dataclasses.replace(scn, transient=scn.duration / 4.0)
        _cross_checks(scn)
    except ConfigError as e:
        path = e.path or ""
        for key, where in reversed(applied):
            if path == key or path.startswith(key + ".") or (path and key.startswith(path + ".")):
                raise e.with_context(f"(from {where})") from None
        raise (e.with_context(label) if label else e) from None
    name = scn.controller.name
    if ":" in name and not allow_code and (allow_code is False or from_file):
        what = f"scenario file {label}" if from_file else "the study"
        raise ConfigError(f"controller.name = {name!r} in {what} is Python code; files run no code unless "
                          "you allow it: add --allow-code (API: allow_code=True) if you trust it, or give "
                          "the controller on the command line (--controller)", path="controller.name")
    return scn


def _prepare(raw: dict, default_name: str | None) -> dict:
    """The scenario table with its defaults that depend on other keys: the name, plant models on top of
    the nominal ones, sub-task weights per kind; the controller's name alone as its table."""
    if "name" not in raw and default_name:
        raw["name"] = default_name
    ctrl = raw.get("controller")
    if isinstance(ctrl, str):
        raw["controller"] = {"name": ctrl.strip()}
    elif isinstance(ctrl, dict):
        if isinstance(ctrl.get("name"), str):
            ctrl["name"] = ctrl["name"].strip()
        if isinstance(ctrl.get("params"), str) and ctrl["params"].strip().lower() == "none":
            ctrl["params"] = {}
    plant = raw.get("plant")
    for sub in ("master", "slave"):
        if isinstance(plant, dict) and isinstance(plant.get(sub), dict):
            nominal = raw.get(sub)
            plant[sub] = {**(nominal if isinstance(nominal, dict) else {}), **plant[sub]}
    sub = raw.get("subtask")
    if isinstance(sub, dict) and "weights" not in sub and isinstance(sub.get("kinds"), list):
        default_w = dict(zip(SubtaskSpec().kinds, SubtaskSpec().weights, strict=True))
        sub["weights"] = [default_w.get(k, 1.0) if isinstance(k, str) else 1.0 for k in sub["kinds"]]
    return raw


def to_toml(v: Any) -> Any:
    """A TOML-ready copy of `v`: dataclasses -> tables in schema order, None -> "none", tuples -> lists."""
    if v is None:
        return "none"
    if type(v) in (bool, int, float, str):  # exact types: numpy scalars (float subclasses) go to .item()
        return v
    if isinstance(v, EnvironmentConfig):  # named objects: [environment.objects.<name>]
        return {"objects": {o.name: {k: x for k, x in to_toml(o).items() if k != "name"}
                            for o in v.objects}}
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: to_toml(getattr(v, f.name)) for f in info(type(v)).fields}
    if isinstance(v, dict):
        return {k: to_toml(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [to_toml(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


scenario_to_dict = to_toml  # the resolved scenario as a TOML-ready dict, every field in schema order


def _toml_lines(table: Mapping[str, Any], name: str = "") -> list[str]:
    lines = [f"[{name}]"] if name else []
    lines += [f"{k} = {toml_literal(v)}" for k, v in table.items() if not isinstance(v, Mapping)]
    for k, v in table.items():
        if isinstance(v, Mapping):
            lines += [""] + _toml_lines(v, f"{name}.{k}" if name else k)
    return lines


def dumps_scenario(scn: Scenario) -> str:
    """The resolved scenario as TOML text; a relative controller file path is written absolute."""
    ref = file_reference(scn.controller.name)
    if ref is not None and not Path(ref[0]).is_absolute():
        scn = dataclasses.replace(scn, controller=dataclasses.replace(
            scn.controller, name=f"{os.path.abspath(ref[0])}:{ref[1]}"))
    header = [
        "# Fully resolved scenario written by harness.config.load.dump_scenario.",
        '# Every value is explicit; "none" = unset (no noise / automatic / same as the nominal model).',
        "# Reproduce with: teleop run <this file>",
        "",
    ]
    text = "\n".join(header + _toml_lines(scenario_to_dict(scn))) + "\n"
    tomllib.loads(text)  # never write a file that does not read back
    return text


def dump_scenario(scn: Scenario, path: str | Path) -> Path:
    """Write the fully resolved scenario as TOML; `load_scenario(path) == scn`."""
    return write_atomic(Path(path), dumps_scenario(scn))


__all__ = [
    "REACH_MARGIN", "dump_scenario", "dumps_scenario", "load_scenario", "parse_override", "scenario_to_dict",
    "to_toml", "trajectory_radius_range",
]
