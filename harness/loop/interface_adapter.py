"""A controller written against `controllers.interface` (``reset(ctx)``, ``step(obs) -> Action``) as the
controller of the one Python-level loop (`harness.loop.stepped_loop.simulate_stepped`).

`InterfaceController` fills the preallocated `Observation` (sensed state (16,), x_d, dx_d, ddx_d (2,),
paper eq. (40), the scenario's interaction forces F (4,) N), calls the controller, checks the
`Action` (shapes, finite values) and copies T1 (2,) N m, T2 (6,), u2 (6,), deN (6,) into the loop's
buffers.  With ``use_ref`` (servo plants) the controller's q2_ref / dq2_ref replace the loop's
integrated reference (`use_ref`, `ref` (12,)).

Failures are one line naming the controller, the step and the time:
* the controller raises, returns None, a wrong shape, NaN or inf -> `ControllerFailure` (the loop stops
  with status "error", rows up to the previous step kept, meta "failed_controller");
* `ControllerDiverged` -> its status code (or -1 with `diverged` holding the message); the row of that
  step is recorded with the controller's last action, as in the compiled loops.
"""

from __future__ import annotations

import numpy as np

from controllers.interface import (
    ControllerContext,
    ControllerDiverged,
    NominalModels,
    Observation,
    ParamsError,
)
from controllers.status import Status
from harness.config.controller import is_compiled, load_class, parse_params, plant_actuation
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.loop.common import RunModel, compile_model
from harness.loop.fast import K

SHAPES = (("T1", 2), ("T2", 6), ("u2", 6), ("deN", 6))
REF_SHAPES = (("q2_ref", 6), ("dq2_ref", 6))


class ControllerFailure(RuntimeError):
    """A controller raised or returned an unusable action (message: one line naming the controller)."""


def _line(e: BaseException) -> str:
    return " ".join(str(e).split())


def check_action(act, name: str, k: int, t: float, servo: bool) -> str:
    """'' if the action is usable, else what is wrong (one line)."""
    where = f"at step {k} (t = {t:.3f} s)"
    if act is None:
        return f"controller {name!r} returned None instead of an Action {where}"
    use_ref = bool(getattr(act, "use_ref", False))
    fields = SHAPES + (REF_SHAPES if servo and use_ref else ())
    for field, n in fields:
        v = getattr(act, field, None)
        if v is None and field == "deN":
            continue
        if not isinstance(v, np.ndarray):
            return (f"controller {name!r} returned {field} of type {type(v).__name__} (expected a numpy "
                    f"array of shape ({n},)) {where}")
        if v.shape != (n,):
            return f"controller {name!r} returned {field} of shape {v.shape} (expected ({n},)) {where}"
        if not np.all(np.isfinite(v)):
            bad = "NaN" if np.any(np.isnan(v)) else "inf"
            text = np.array2string(v, precision=4)
            return f"controller {name!r} returned {bad} in {field} = {text} {where}"
    return ""


class InterfaceController:
    """The scenario's `controllers.interface.Controller` (built-in or user class) as the loop's
    controller: ``reset(model)``, ``step(t, sensed, xd, dxd, ddxd, T1, T2, u2, deN) -> int``."""

    def __init__(self, scn: Scenario, model: RunModel) -> None:
        self.name = scn.controller.name
        self.ctrl, self.ctx = make_controller(scn, model)
        self.servo = self.ctx.actuation == "servo"
        self.obs = Observation()
        self.F = self.obs.F  # (4,) N, the sensed tip forces: the loop writes them here before each step
        self.use_ref = False
        self.ref = np.zeros(12)  # [q2_ref, dq2_ref] of the last action with use_ref
        self.diverged = ""
        self.k = 0

    def reset(self, model: RunModel) -> None:
        self.obs.F[:] = model.F
        self.k = 0
        try:
            self.ctrl.reset(self.ctx)
        except Exception as e:  # noqa: BLE001 - the controller's fault: one line
            raise ControllerFailure(f"controller {self.name!r} raised {type(e).__name__} in reset: "
                                    f"{_line(e)}") from None

    def step(self, t, sensed, xd, dxd, ddxd, T1, T2, u2, deN) -> int:
        obs, name, k = self.obs, self.name, self.k
        self.k = k + 1
        obs.sensed[:] = sensed
        obs.x_d[:] = xd
        obs.dx_d[:] = dxd
        obs.ddx_d[:] = ddxd
        obs.t, obs.k = t, k
        code = 0
        try:
            act = self.ctrl.step(obs)
        except ControllerDiverged as e:
            code = e.code if e.code in Status._value2member_map_ and e.code != 0 else -1
            self.diverged = f"controller {name!r} stopped: {_line(e)} at step {k} (t = {t:.3f} s)"
            act = getattr(self.ctrl, "action", None)
            if act is None:
                raise ControllerFailure(self.diverged) from None
        except Exception as e:  # noqa: BLE001 - the controller's fault: one line
            raise ControllerFailure(f"controller {name!r} raised {type(e).__name__}: {_line(e)} "
                                    f"at step {k} (t = {t:.3f} s)") from None
        bad = check_action(act, name, k, t, self.servo)
        if bad:
            raise ControllerFailure(bad)
        T1[:] = act.T1
        T2[:] = act.T2
        u2[:] = act.u2
        if getattr(act, "deN", None) is not None:
            deN[:] = act.deN
        else:
            deN[:] = 0.0
        self.use_ref = self.servo and bool(getattr(act, "use_ref", False))
        if self.use_ref:
            self.ref[0:6] = act.q2_ref
            self.ref[6:12] = act.dq2_ref
        return code


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


__all__ = ["ControllerFailure", "InterfaceController", "is_compiled", "make_controller"]
