"""The scenario's controller class: a built-in or user code ("path/to/file.py:ClassName",
"package.module:ClassName"; the one place that imports a module by name), checked against the plant before
anything runs.  While the main thread runs controller code `USER_CODE[0]` is True (signal handlers use it)."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import importlib.util
import sys
from pathlib import Path

from controllers.baselines import BUILTINS, FAST_PATH
from controllers.interface import Controller, ParamsError
from harness.config.errors import ConfigError
from harness.config.load import file_reference, to_toml
from harness.config.scenario import Scenario
from harness.config.schema import decode, did_you_mean, suggest
from harness.config.textio import toml_literal


class HarnessInterrupt(KeyboardInterrupt):
    """A Ctrl-C / SIGTERM of the user (a controller's own KeyboardInterrupt is its failure)."""


class ControllerCodeError(ConfigError):
    """A controller's own code failed before the run (import, Params check): one line, exit 1."""

    exit_code = 1


USER_CODE = [False]


def describe_exception(e: BaseException) -> str:
    """'SystemExit(0)', 'KeyboardInterrupt', 'RuntimeError: boom' (one line)."""
    if isinstance(e, SystemExit):
        return f"SystemExit({e.code!r})"
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def describe_builtins() -> list[tuple[str, str, tuple[str, ...]]]:
    """(name, one-line description, supported actuations) of every built-in."""
    return [(n, c.description + ("; compiled fast path" if n == FAST_PATH else
                                  " (through the Python interface)" if c is BUILTINS[FAST_PATH] else ""),
             tuple(c.actuations)) for n, c in BUILTINS.items()]


def plant_actuation(scn: Scenario) -> str:
    """What the plant needs from the slave command: "torque" (T2) or "servo" (u2 / reference)."""
    return "servo" if scn.plant.kind != "analytic" and scn.plant.actuation == "servo" else "torque"


def _bad(name: str, why: str) -> ConfigError:
    return ConfigError(f"controller.name = {name!r}: {why}", path="controller.name")


def load_class(name: str) -> type:
    """The controller class named `name` (built-in, file path or module path), or ConfigError."""
    if name in BUILTINS:
        return BUILTINS[name]
    if ":" not in name:
        hint = did_you_mean(suggest(name, BUILTINS))
        raise _bad(name, f"unknown built-in controller; {hint}built-ins: {', '.join(BUILTINS)}; or give "
                         "'file.py:ClassName' or 'package.module:ClassName'")
    where, _, attr = name.rpartition(":")
    try:
        if file_reference(name):
            path = Path(where)
            if not path.is_file():
                raise _bad(name, f"file {where} not found")
            digest = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]
            modname = "teleop_user_controller_" + digest
            mod = sys.modules.get(modname)
            if mod is None:
                spec = importlib.util.spec_from_file_location(modname, path)
                mod = importlib.util.module_from_spec(spec)
                sys.modules[modname] = mod  # dataclasses and pickling need it registered
                try:
                    spec.loader.exec_module(mod)
                except BaseException:
                    sys.modules.pop(modname, None)
                    raise
        else:
            mod = importlib.import_module(where)
    except (ConfigError, HarnessInterrupt):
        raise
    except (SystemExit, KeyboardInterrupt) as e:  # user code tried to end the process: an error
        raise ControllerCodeError(f"controller.name = {name!r}: importing {where} raised "
                                  f"{describe_exception(e)}", path="controller.name") from None
    except Exception as e:  # noqa: BLE001 - any import failure is one line
        raise _bad(name, f"cannot import {where}: {describe_exception(e)}") from None
    cls = getattr(mod, attr, None)
    if cls is None:
        raise _bad(name, f"{where} has no attribute {attr!r}")
    if not isinstance(cls, type):
        raise _bad(name, f"{attr} is not a class (a controller is a class with reset(ctx) and step(obs))")
    missing = [m for m in ("reset", "step") if not callable(getattr(cls, m, None))]
    if issubclass(cls, Controller) and cls.step is Controller.step:
        missing.append("step")  # the base class' step only raises NotImplementedError
    if missing:
        raise _bad(name, f"class {attr} lacks the controller interface: no method {' or '.join(missing)} "
                         "(see controllers/interface.py)")
    return cls


def parse_params(cls: type, raw: dict | None, name: str | None = None):
    """The validated `Params` of `cls` (None for a class without) from its [controller.params] table.
    Raises ConfigError (one line), ControllerCodeError for anything else its check raises."""
    params, raw = getattr(cls, "Params", None), dict(raw or {})
    label = name or getattr(cls, "name", cls.__name__)
    if params is None and raw:
        key = sorted(raw)[0]
        raise ConfigError.field(f"controller.params.{key}", raw[key],
                                f"unknown key; controller {label!r} takes no parameters")
    if params is None:
        return None
    if not dataclasses.is_dataclass(params):
        raise ConfigError(f"controller {label!r}: its Params must be a dataclass with defaults",
                          path="controller.params")
    try:
        p = decode(raw, params, prefix="controller.params.")
        if callable(getattr(p, "check", None)):
            p.check()
    except (ConfigError, HarnessInterrupt):
        raise
    except ParamsError as e:
        raise ConfigError(str(e), path=f"controller.params.{e.key}") from None
    except (TypeError, ValueError) as e:
        raise ConfigError(f"controller.params (controller {label!r}): {' '.join(str(e).split())}",
                          path="controller.params") from None
    except BaseException as e:  # noqa: BLE001 - the controller's code: one line
        raise ControllerCodeError(f"controller {label!r} raised {describe_exception(e)} in its Params check",
                                  path="controller.params") from None
    return p


def resolve_controller(scn: Scenario) -> Scenario:
    """The scenario with its controller's params spelled out, after checking the class, its actuations,
    plants and requirements and the params.  Raises ConfigError (one line)."""
    cfg = scn.controller
    cls = load_class(cfg.name)
    act = plant_actuation(scn)
    plants = getattr(cls, "plants", None)
    if plants is not None and scn.plant.kind not in plants:
        raise _bad(cfg.name, f"runs on plant.kind {', '.join(map(repr, plants))} only, not "
                             f"{scn.plant.kind!r}")
    supported = tuple(getattr(cls, "actuations", ("torque", "servo")))
    if act not in supported:
        plant = "the analytic plant (torque-driven)" if scn.plant.kind == "analytic" else \
            f"plant.actuation = {act!r}"
        need = "T2 (section forces/moments)" if act == "torque" else "u2 or a servo reference"
        raise _bad(cfg.name, f"supports actuation {', '.join(map(repr, supported))} only, but {plant} "
                             f"needs {need}")
    for key, want in (getattr(cls, "requires", None) or {}).get(scn.plant.kind, {}).items():
        have = functools.reduce(lambda obj, part: getattr(obj, part, None), key.split("."), scn)
        if have != want:
            raise _bad(cfg.name, f"needs {key} = {toml_literal(want)} on plant.kind {scn.plant.kind!r} "
                                 f"(it is {toml_literal(have)})")
    p = parse_params(cls, cfg.params, cfg.name)
    full = to_toml(p) if dataclasses.is_dataclass(p) else dict(cfg.params)
    if cfg.name == FAST_PATH or full == cfg.params:
        return scn
    return dataclasses.replace(scn, controller=dataclasses.replace(cfg, params=full))


def is_compiled(scn: Scenario) -> bool:
    """True when the paper's law runs in the compiled fast path (`controller.name = "paper"`)."""
    return scn.controller.name == FAST_PATH


__all__ = ["USER_CODE", "ControllerCodeError", "HarnessInterrupt", "describe_builtins", "describe_exception",
           "is_compiled", "load_class", "parse_params", "plant_actuation", "resolve_controller"]
