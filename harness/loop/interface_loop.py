"""Closed loop for a controller written in Python (`controllers.interface.Controller`), on any plant
with a Python-stepped adapter (`harness.loop.stepped_plants`).

Per control step k (t = k dt), the same sequence as the compiled loops:
  true state (plant) -> x_d(t) (eq. (40)) -> sensed = true state + AWGN (seeded table) ->
  controller.step(obs) -> checks of the action -> record row of the true state -> runaway check ->
  plant.command -> plant.advance (substeps).
The harness allocates nothing per step (the Observation, the state, the rows are preallocated; the
controller owns its Action).  A controller that raises, returns a wrong shape, NaN or inf stops the run:
status "error", message naming the controller, the step and the time; rows up to the previous step are
kept.  `ControllerDiverged` from the controller stops the run with status "diverged".
"""

from __future__ import annotations

import time

import numpy as np

from controllers.interface import ControllerDiverged, Observation
from harness.config.scenario import Scenario
from harness.loop.common import (
    CHUNK,
    STATUS_TEXT,
    STOP,
    common_arrays,
    noise_table,
    progress_bar,
    run_meta,
    set_outcome,
)
from harness.loop.controllers import make_controller
from harness.loop.fast import K
from harness.loop.kernels import R_E1, R_E2, RUNAWAY
from harness.loop.stepped_plants import stepped_plant
from harness.loop.trajectory import ROW_WIDTH, Trajectory

SHAPES = (("T1", 2), ("T2", 6), ("u2", 6), ("deN", 6))
REF_SHAPES = (("q2_ref", 6), ("dq2_ref", 6))


class ControllerFailure(RuntimeError):
    """A controller raised or returned an unusable action (message: what, naming the controller)."""


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


def simulate_controller(scn: Scenario, progress: bool = False, plant=None, on_chunk=None) -> Trajectory:
    """Run the scenario with its (Python) controller; returns the Trajectory (possibly cut short).
    on_chunk: optional callable receiving every CHUNK steps as a `Trajectory` (time series only)."""
    name = scn.controller.name
    tb = time.perf_counter()
    ctrl, ctx = make_controller(scn)
    sp = stepped_plant(scn, plant)
    build_time = time.perf_counter() - tb
    n, dt = scn.n_steps, scn.control_dt
    a = common_arrays(scn)
    noise, scale = noise_table(scn, n)
    rows = np.zeros((n, ROW_WIDTH))
    obs = Observation()
    obs.F[:] = a["F"]
    state = np.empty(16)
    traj_p, mpk, gains, spec = a["traj"], a["mpk_c"], a["gains"], a["spec"]
    servo = ctx.actuation == "servo"
    status, done, error, interrupted, diverged = 0, 0, "", False, ""
    bar = progress_bar(progress, n, f"{scn.plant.kind} plant, controller {name}")
    t0 = time.perf_counter()
    try:
        ctrl.reset(ctx)
    except Exception as e:  # noqa: BLE001 - the controller's fault: one line
        error = f"controller {name!r} raised {type(e).__name__} in reset: {' '.join(str(e).split())}"
        n = 0
    try:
        for k in range(n):
            t = k * dt
            status = sp.true_state(state)
            if status:
                break
            K.desired(traj_p, t, obs.x_d, obs.dx_d, obs.ddx_d)
            if scale > 0.0:
                K.add_noise(state, noise[k], scale, obs.sensed)
            else:
                obs.sensed[:] = state
            obs.t, obs.k = t, k
            try:
                act = ctrl.step(obs)
            except ControllerDiverged as e:
                status = e.code if e.code in STATUS_TEXT else -1
                diverged = (f"controller {name!r} stopped: {' '.join(str(e).split())} "
                            f"at step {k} (t = {t:.3f} s)")
                act = ctrl.action if hasattr(ctrl, "action") else None
                if act is not None:
                    K.record_row(t, state, obs.x_d, obs.dx_d, mpk, gains, spec, act.T1, act.T2, act.u2,
                                 act.deN, rows[k])
                    done = k + 1
                break
            except Exception as e:  # noqa: BLE001 - the controller's fault: one line
                error = (f"controller {name!r} raised {type(e).__name__}: {' '.join(str(e).split())} "
                         f"at step {k} (t = {t:.3f} s)")
                break
            bad = check_action(act, name, k, t, servo)
            if bad:
                error = bad
                break
            deN = act.deN if getattr(act, "deN", None) is not None else np.zeros(6)
            K.record_row(t, state, obs.x_d, obs.dx_d, mpk, gains, spec, act.T1, act.T2, act.u2, deN, rows[k])
            sp.record_start(k)
            done = k + 1
            r = rows[k]
            if abs(r[R_E1]) + abs(r[R_E1 + 1]) > RUNAWAY or abs(r[R_E2]) + abs(r[R_E2 + 1]) > RUNAWAY:
                status = 4
                break
            sp.command(k, obs.sensed, act)
            status = sp.advance()
            if status:
                break
            if bar is not None and k % 250 == 249:
                bar.update(250)
            if on_chunk is not None and (k + 1) % CHUNK == 0:
                part = Trajectory.from_rows(rows[k + 1 - CHUNK:k + 1])
                part.meta.update(run_meta(scn, 0.0))
                on_chunk(part)
            if STOP.is_set():
                interrupted = True
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    traj = Trajectory.from_rows(rows[:done])
    traj.meta.update(run_meta(scn, wall))
    traj.meta["build_time"] = build_time
    traj.meta["controller"] = name
    sp.finish(traj, done)
    if error:
        traj.status, traj.message = "error", error
        traj.meta["failed_controller"] = name
    elif status == -1:
        traj.status, traj.message = "diverged", diverged
    else:
        set_outcome(traj, status, interrupted)
    return traj
