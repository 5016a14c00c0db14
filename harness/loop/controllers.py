"""Controller selection: the registry of built-ins, the importer for user classes, parameter
validation and the per-run controller context.  The interface itself is `controllers.interface`.

`scn.controller.name`:
* "paper" (default): the paper's law, fused into the compiled loops (harness.loop.kernels) -- the
  fast path, no Python per step;
* another built-in (`BUILTINS`), or "path/to/file.py:ClassName" / "package.module:ClassName": the
  class runs through the Python-level loop (harness.loop.stepped_loop) on the same plants, noise,
  metrics and recordings.

`resolve_controller(scn)` loads and checks the class (ConfigError, exit 2, before anything is written):
it must be a class with callable `reset` and `step`, support the plant's actuation, accept the
scenario's params; it returns the scenario with every parameter spelled out (for config.toml).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import importlib.util
import sys
from pathlib import Path

import numpy as np

from controllers.baselines import DampedLeastSquaresIK, PaperNoNullSpace
from controllers.control import MASTER_INFO, SLAVE_INFO
from controllers.interface import (
    Action,
    Controller,
    ControllerContext,
    ControllerDiverged,
    NominalModels,
    Observation,
    ParamsError,
)
from harness.config.errors import ConfigError
from harness.config.scenario import ControllerConfig, Scenario
from harness.loop.common import RunModel, compile_model
from harness.loop.fast import K
from harness.plant.status import Status

COMPILED = "paper"  # the name that selects the compiled fast path


class PaperController(Controller):
    """The paper's law (12)-(13), (17)-(18) with the null-space terms (23)-(33) through the interface:
    each step calls the same compiled kernel as the fused loop (`harness.loop.kernels.control_laws`)
    on the observation, so a run gives the compiled loop's numbers bit for bit (tested)."""

    name = "paper_interface"
    description = "the paper's law (12)-(33) through the Python interface (compiled kernels per step)"
    actuations = ("torque", "servo")

    def reset(self, ctx: ControllerContext) -> None:
        super().reset(ctx)
        m = ctx.models
        self.gains = np.concatenate([ctx.gains.packed(), [float(ctx.faults[0]), float(ctx.faults[1])]])
        self.args = (m.mpk, m.spk, m.nodes, m.weights, self.gains, m.spec)
        self.minfo, self.sinfo = np.empty(MASTER_INFO), np.empty(SLAVE_INFO)

    def step(self, obs: Observation) -> Action:
        a = self.action
        st = K.control_laws(*self.args, obs.sensed, obs.x_d, obs.dx_d, obs.ddx_d, obs.F, a.T1, a.T2, a.u2,
                            a.deN, self.minfo, self.sinfo)
        if st != 0:
            raise ControllerDiverged(Status(st).text, code=st)
        return a


# name -> class; "paper" is listed with the class that gives the same law through the interface
BUILTINS: dict[str, type] = {
    "paper": PaperController,
    "paper_interface": PaperController,
    "paper_no_null": PaperNoNullSpace,
    "dls_ik": DampedLeastSquaresIK,
}
DESCRIPTIONS = {
    "paper": "the paper's law (12)-(13), (17)-(18) with null-space terms (23)-(33); compiled fast path",
}


def describe_builtins() -> list[tuple[str, str, tuple[str, ...]]]:
    """(name, one-line description, supported actuations) of every built-in."""
    return [(n, DESCRIPTIONS.get(n, c.description), tuple(c.actuations)) for n, c in BUILTINS.items()]


def plant_actuation(scn: Scenario) -> str:
    """What the plant needs from the slave command: "torque" (T2) or "servo" (u2 / reference)."""
    return "torque" if scn.plant.kind == "analytic" else scn.plant.actuation


def _bad(name: str, why: str) -> ConfigError:
    return ConfigError(f"controller.name = {name!r}: {why}", path="controller.name", value=name)


def load_class(name: str) -> type:
    """The controller class named `name` (built-in, file path or module path), or ConfigError."""
    if name in BUILTINS:
        return BUILTINS[name]
    if ":" not in name:
        close = ", ".join(BUILTINS)
        raise _bad(name, f"unknown built-in controller (built-ins: {close}; or give 'file.py:ClassName' "
                         "or 'package.module:ClassName')")
    where, _, attr = name.rpartition(":")
    try:
        if where.endswith(".py") or "/" in where or "\\" in where:
            path = Path(where)
            if not path.is_file():
                raise _bad(name, f"file {where} not found")
            digest = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]
            modname = "teleop_user_controller_" + digest
            mod = sys.modules.get(modname)
            if mod is None:
                spec = importlib.util.spec_from_file_location(modname, path)
                mod = importlib.util.module_from_spec(spec)
                sys.modules[modname] = mod  # dataclasses and pickling need the module registered
                try:
                    spec.loader.exec_module(mod)
                except BaseException:
                    sys.modules.pop(modname, None)
                    raise
        else:
            mod = importlib.import_module(where)
    except ConfigError:
        raise
    except Exception as e:  # noqa: BLE001 - any import failure is one line
        raise _bad(name, f"cannot import {where}: {type(e).__name__}: {' '.join(str(e).split())}") from None
    cls = getattr(mod, attr, None)
    if cls is None:
        raise _bad(name, f"{where} has no attribute {attr!r}")
    if not isinstance(cls, type):
        raise _bad(name, f"{attr} is not a class (a controller is a class with reset(ctx) and step(obs))")
    missing = [m for m in ("reset", "step") if not callable(getattr(cls, m, None))]
    if missing:
        raise _bad(name, f"class {attr} lacks the controller interface: no method {' or '.join(missing)} "
                         "(see controllers/interface.py)")
    return cls


def parse_params(cls: type, raw: dict):
    """Validated params of `cls` (its `parse_params` classmethod, or the base class' rules)."""
    fn = getattr(cls, "parse_params", None)
    if fn is None:
        return Controller.parse_params.__func__(cls, raw)
    return fn(raw)


def _as_toml(v):
    if isinstance(v, (list, tuple)):
        return [_as_toml(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def resolve_controller(scn: Scenario) -> Scenario:
    """Load and check the scenario's controller; returns the scenario with its params spelled out.
    Raises ConfigError (one line) for an unknown/unimportable class, a missing interface, an actuation
    the controller does not support, or a bad parameter."""
    cfg = scn.controller
    cls = load_class(cfg.name)
    act = plant_actuation(scn)
    supported = tuple(getattr(cls, "actuations", ("torque", "servo")))
    if act not in supported:
        plant = "the analytic plant (torque-driven)" if scn.plant.kind == "analytic" else \
            f"plant.actuation = {act!r}"
        need = "T2 (section forces/moments)" if act == "torque" else "u2 or a servo reference"
        raise _bad(cfg.name, f"supports actuation {', '.join(map(repr, supported))} only, but {plant} "
                             f"needs {need}")
    try:
        p = parse_params(cls, cfg.params)
    except ParamsError as e:
        raise ConfigError(str(e), path=f"controller.params.{e.key}") from None
    except (TypeError, ValueError) as e:
        raise ConfigError(f"controller.params (controller {cfg.name!r}): {' '.join(str(e).split())}",
                          path="controller.params") from None
    full = ({f.name: _as_toml(getattr(p, f.name)) for f in dataclasses.fields(p)}
            if dataclasses.is_dataclass(p) else dict(cfg.params))
    if cfg.name == COMPILED or full == cfg.params:
        return scn
    return dataclasses.replace(scn, controller=ControllerConfig(cfg.name, full))


def is_compiled(scn: Scenario) -> bool:
    """True when the compiled fast path runs (the paper's law, `controller.name = "paper"`)."""
    return scn.controller.name == COMPILED


def make_controller(scn: Scenario, model: RunModel | None = None):
    """(instance, context) for a run: the class instantiated and the context its `reset` receives.
    model: the scenario's `RunModel` (default: compiled here)."""
    cfg = scn.controller
    cls = load_class(cfg.name)
    try:
        params = parse_params(cls, cfg.params)
    except ParamsError as e:
        raise ConfigError(str(e), path=f"controller.params.{e.key}") from None
    ctrl = cls()
    a = model if model is not None else compile_model(scn)
    ctx = ControllerContext(
        dt=scn.control_dt, n_steps=scn.n_steps, actuation=plant_actuation(scn), plant=scn.plant.kind,
        master=scn.master, slave=scn.slave, gains=scn.gains, subtask=scn.subtask,
        F=a.F.reshape(2, 2).copy(), seed=scn.seed, params=params,
        models=NominalModels(scn.master, scn.slave, scn.subtask, kernels=K), q0=a.s0.copy(),
        faults=(scn.faults.e2_sign, scn.faults.null_space_scale))
    return ctrl, ctx


__all__ = ["BUILTINS", "PaperController", "describe_builtins", "is_compiled", "load_class", "make_controller",
           "plant_actuation", "resolve_controller"]
