"""A `controllers.interface.Controller` as the controller of `harness.loop.stepped_loop`.  Anything it
raises, an unusable action or a call past `controller.step_timeout` -> `ControllerFailure` (one line);
Ctrl-C / SIGTERM -> `HarnessInterrupt`; `ControllerDiverged` -> its status code (else -1)."""

from __future__ import annotations

import signal
import threading
import time

import numpy as np

from controllers.interface import ControllerContext, ControllerDiverged, NominalModels, Observation
from controllers.status import Status
from harness.config.controller import (
    USER_CODE,
    HarnessInterrupt,
    describe_exception,
    is_compiled,
    load_class,
    parse_params,
    plant_actuation,
)
from harness.config.scenario import Scenario
from harness.loop.common import STOP, RunModel, compile_model
from harness.loop.fast import K

SHAPES = (("T1", 2), ("T2", 6), ("u2", 6), ("deN", 6))
REF_SHAPES = (("q2_ref", 6), ("dq2_ref", 6))
FIRST_CALL_TIMEOUT = 120.0  # s at least for construction, reset and step 0 (they may compile kernels)
_TIMER = hasattr(signal, "setitimer")
STATUS_CODES = frozenset(int(s) for s in Status)


class ControllerFailure(RuntimeError):
    """A controller raised or returned an unusable action (message: one line naming the controller)."""


class _Timeout(BaseException):
    """Raised by the alarm handler inside a controller call that ran past its limit."""


def _on_alarm(signum, frame):  # noqa: ARG001
    if USER_CODE[0]:
        raise _Timeout


def _on_sigint(signum, frame):  # noqa: ARG001 - Python's default Ctrl-C, marked as the user's
    raise HarnessInterrupt


def check_action(act, name: str, k: int, t: float, servo: bool) -> str:
    """'' if the action is usable, else what is wrong (one line naming the field)."""
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
        if v.dtype.kind not in "fiu":  # complex (its imaginary part would be dropped), bool, str, object
            return (f"controller {name!r} returned {field} of dtype {v.dtype} (expected real floating-point "
                    f"numbers) {where}")
        if not np.all(np.isfinite(v)):
            bad = "NaN" if np.any(np.isnan(v)) else "inf"
            text = np.array2string(v, precision=4)
            return f"controller {name!r} returned {bad} in {field} = {text} {where}"
    return ""


class InterfaceController:
    """The scenario's controller as the loop's: ``reset(model)``, ``step(t, sensed, xd, dxd, ddxd, T1, T2,
    u2, deN) -> status`` (fills the `Observation`, checks the `Action`, copies T1 (2,) N m, T2, u2, deN (6,)
    and, with ``use_ref`` on a servo plant, `ref` = [q2_ref, dq2_ref]), ``close()``.  A failed
    construction is raised by `reset`."""

    def __init__(self, scn: Scenario, model: RunModel) -> None:
        self.name = scn.controller.name
        self.limit = scn.controller.step_timeout  # s per step, None = no limit
        self.main = threading.current_thread() is threading.main_thread()
        self._saved: dict | None = None  # signal handlers replaced for the controller's calls
        self.failure = ""
        self.ctrl, self.ctx = make_controller(scn, model, construct=False)
        try:
            self.ctrl = self._once("construction", self.ctrl)
        except ControllerFailure as e:
            self.ctrl, self.failure = None, str(e)
        self.servo = self.ctx.actuation == "servo"
        self.obs = Observation()
        self.F = self.obs.F  # (4,) N, the sensed tip forces: the loop writes them here before each step
        self.use_ref = False
        self.ref = np.zeros(12)  # [q2_ref, dq2_ref] of the last action with use_ref
        self.diverged = ""
        self.k = 0

    def _install(self) -> None:
        """On the main thread: the time limit's alarm handler; default Ctrl-C marked as the user's."""
        if self._saved is not None or not self.main:
            return
        self._saved = {}
        if self.limit is not None and _TIMER:
            self._saved[signal.SIGALRM] = signal.signal(signal.SIGALRM, _on_alarm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._saved[signal.SIGINT] = signal.signal(signal.SIGINT, _on_sigint)

    def close(self) -> None:
        """Disarm the timer and restore the signal handlers (idempotent)."""
        if self._saved is None:
            return
        if signal.SIGALRM in self._saved:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
        for sig, old in self._saved.items():
            signal.signal(sig, old)
        self._saved = None

    def _fail(self, e: BaseException, phase: str, limit: float | None) -> ControllerFailure:
        if isinstance(e, _Timeout):
            return ControllerFailure(f"controller {self.name!r} ran longer than controller.step_timeout = "
                                     f"{limit:g} s {phase} (stopped; raise or turn off the limit with "
                                     "controller.step_timeout = \"none\")")
        return ControllerFailure(f"controller {self.name!r} raised {describe_exception(e)} {phase}")

    def _call(self, where: str, limit: float | None, fn, *args):
        """Call controller code under the time limit (s, None: none; `where` names the phase): anything
        raised but `HarnessInterrupt` / `ControllerDiverged`, or past the limit: `ControllerFailure`."""
        self._install()
        armed = self.main and limit is not None and _TIMER
        USER_CODE[0] = self.main
        t0 = time.perf_counter()
        try:
            if armed:
                signal.setitimer(signal.ITIMER_REAL, limit)
            out = fn(*args)
        except (HarnessInterrupt, ControllerDiverged):
            raise
        except BaseException as e:  # noqa: BLE001 - the controller's code: one line, never the process
            if isinstance(e, KeyboardInterrupt) and STOP.is_set():
                raise HarnessInterrupt from None  # the user's Ctrl-C reached the controller's code
            raise self._fail(e, where, limit) from None
        finally:
            USER_CODE[0] = False
        if limit is not None and not armed and time.perf_counter() - t0 > limit:  # worker threads: no alarm
            raise self._fail(_Timeout(), where, limit)
        return out

    def _once(self, phase: str, fn, *args):
        """Call controller code once (construction, reset) under the first-call time limit."""
        limit = None if self.limit is None else max(self.limit, FIRST_CALL_TIMEOUT)
        try:
            return self._call(f"in {phase}", limit, fn, *args)
        except ControllerDiverged as e:  # before the run: the controller's failure, not a divergence
            raise self._fail(e, f"in {phase}", limit) from None
        finally:
            self.close()

    def reset(self, model: RunModel) -> None:
        self.obs.F[:] = model.F
        self.k = 0
        if self.ctrl is None:
            raise ControllerFailure(self.failure)
        self._once("reset", self.ctrl.reset, self.ctx)

    def step(self, t, sensed, xd, dxd, ddxd, T1, T2, u2, deN) -> int:
        obs, name, k = self.obs, self.name, self.k
        self.k = k + 1
        obs.sensed[:] = sensed
        obs.x_d[:] = xd
        obs.dx_d[:] = dxd
        obs.ddx_d[:] = ddxd
        obs.t, obs.k = t, k
        code = 0
        limit = self.limit
        if limit is not None and k == 0:
            limit = max(limit, FIRST_CALL_TIMEOUT)
        try:
            act = self._call(f"at step {k} (t = {t:.3f} s)", limit, self.ctrl.step, obs)
        except ControllerDiverged as e:
            code = e.code if e.code in STATUS_CODES and e.code != 0 else -1
            why = " ".join(str(e).split())
            self.diverged = f"controller {name!r} stopped: {why} at step {k} (t = {t:.3f} s)"
            act = getattr(self.ctrl, "action", None)
            if act is None:
                raise ControllerFailure(self.diverged) from None
        bad = check_action(act, name, k, t, self.servo)
        if bad:
            raise ControllerFailure(bad)
        T1[:] = act.T1
        T2[:] = act.T2
        u2[:] = act.u2
        deN[:] = act.deN if getattr(act, "deN", None) is not None else 0.0
        self.use_ref = self.servo and bool(getattr(act, "use_ref", False))
        if self.use_ref:
            self.ref[0:6] = act.q2_ref
            self.ref[6:12] = act.dq2_ref
        return code


def make_controller(scn: Scenario, model: RunModel | None = None, construct: bool = True):
    """(instance, the context its `reset` receives); construct=False: (the class, context)."""
    cfg = scn.controller
    cls = load_class(cfg.name)
    params = parse_params(cls, cfg.params, cfg.name)
    a = model if model is not None else compile_model(scn)
    ctx = ControllerContext(
        dt=scn.control_dt, n_steps=scn.n_steps, actuation=plant_actuation(scn), plant=scn.plant.kind,
        master=scn.master, slave=scn.slave, gains=scn.gains, subtask=scn.subtask,
        F=a.F.reshape(2, 2).copy(), seed=scn.seed, params=params,
        models=NominalModels(scn.master, scn.slave, scn.subtask, kernels=K), q0=a.s0.copy(),
        faults=(scn.faults.e2_sign, scn.faults.null_space_scale))
    return (cls() if construct else cls), ctx


__all__ = ["ControllerFailure", "InterfaceController", "is_compiled", "make_controller"]
