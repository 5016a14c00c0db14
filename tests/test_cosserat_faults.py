"""The Cosserat rod under faults: a configuration needing too many rod steps per control step is refused
in one line before anything runs; the rod's stepping stops between bounded batches (the run's stop flag,
Ctrl-C); a numeric blow-up inside the rod step is a divergence with the time, not an exception.
Cheap configurations (3 elements per section, short runs)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from controllers.params import SlaveParams
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.loop import simulate
from harness.loop.common import STOP
from harness.plant import validate_plant
from harness.plant.cosserat import CosseratSlave
from harness.plant.cosserat.rod import BATCH_STEPS, MAX_STEPS_PER_CONTROL, RodStopped, stable_dt

ROOT = Path(__file__).resolve().parents[1]
TINY = "plant.slave.masses=[1e-6,1e-6,1e-6]"  # stable rod step ~1e-10 s: ~1e7 rod steps per control step
P = SlaveParams()
Q0 = np.array([*P.rest_lengths, 0.0, 0.0, 0.0])


# --- too many rod steps per control step ------------------------------------------------------------------
def test_tiny_masses_are_refused_in_one_line_by_plant_validation():
    scn = load_scenario(None, ["plant.kind=cosserat", TINY])
    with pytest.raises(ConfigError) as ei:
        validate_plant(scn)
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith("plant.cosserat.dt = 'auto'")
    assert f"more than the limit {MAX_STEPS_PER_CONTROL}" in msg and "rod steps" in msg


def test_limit_is_checked_against_the_stable_step():
    """Refused exactly when control_dt / stable step exceeds the limit: the default rod is far below it."""
    tiny = replace(P, masses=(1e-6, 1e-6, 1e-6))
    assert 1e-3 / stable_dt(P) < MAX_STEPS_PER_CONTROL / 50
    assert 1e-3 / stable_dt(tiny) > MAX_STEPS_PER_CONTROL
    with pytest.raises(ValueError, match="rod steps of"):
        CosseratSlave(tiny, elements_per_section=3)
    CosseratSlave(P, elements_per_section=3)  # the default material is accepted


def test_a_set_step_that_is_too_small_is_refused():
    scn = load_scenario(None, ["plant.kind=cosserat", "plant.cosserat.dt=5e-7"])  # 2000 steps per 1 ms
    with pytest.raises(ConfigError, match="plant.cosserat.dt = 5e-07: 2000 rod steps"):
        validate_plant(scn)


def test_cli_tiny_masses_exit_2_one_line_before_running(tmp_path):
    r = subprocess.run([sys.executable, "-m", "harness.cli", "run", "--plant", "cosserat", "--set", TINY,
                        "--duration", "0.1", "--no-progress", "--out", str(tmp_path / "x")],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "rod steps" in lines[0], r.stderr
    assert not (tmp_path / "x").exists()


# --- interrupts -------------------------------------------------------------------------------------------
def test_rod_step_stops_between_batches_when_its_stop_flag_is_set():
    s = CosseratSlave(P, elements_per_section=3)
    s.reset(Q0)
    s.stop = threading.Event()
    s.stop.set()
    with pytest.raises(RodStopped):
        s.step(Q0, 3 * BATCH_STEPS * s.dt)
    assert s.time == pytest.approx(BATCH_STEPS * s.dt)  # one whole batch, then the stop
    assert np.isfinite(s.tip()).all()


def test_ctrl_c_interrupts_a_long_rod_step():
    """A SIGINT during one long rod step interrupts it between batches (not after all its steps)."""
    s = CosseratSlave(P, elements_per_section=3)
    s.reset(Q0)
    n = 200 * BATCH_STEPS  # seconds of work: far longer than the signal's delay
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.05, lambda: signal.raise_signal(signal.SIGINT))
    try:
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            s.step(Q0, n * s.dt)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, old)
    assert 0.0 < s.time < 0.5 * n * s.dt


def test_run_stop_flag_interrupts_the_rod_within_a_control_step():
    """The harness's stop flag (set by the first Ctrl-C) reaches the rod's inner loop: with 800 rod steps
    per control step the run stops in its first control step, not at the loop's next chunk of steps."""
    scn = load_scenario(None, ["plant.kind=cosserat", "plant.cosserat.elements_per_section=3",
                               "plant.cosserat.dt=1.25e-6", "duration=0.5"])
    STOP.set()
    try:
        tr = simulate(scn)
    finally:
        STOP.clear()
    assert tr.status == "interrupted"
    assert len(tr) == 1


# --- numeric blow-ups -------------------------------------------------------------------------------------
def test_rod_blow_up_is_a_divergence_not_an_exception():
    """A 1.4 kN tip load crushes a 3-element rod within 20 ms: `step` returns False (never raises) and
    never reports success on an exploded state."""
    s = CosseratSlave(P, elements_per_section=3, shear_factor=10.0)
    s.reset(Q0)
    s.external_tip_force([1e3, -1e3])
    far = 10.0 * sum(P.rest_lengths)
    for _ in range(300):
        ok = s.step(Q0, 1e-3)
        if not ok:
            break
        assert np.abs(s._b.position_collection).max() <= far
        s.sense()
    assert not ok
    assert 0.0 < s.time < 0.3


def test_blow_up_inside_the_rod_step_is_reported_as_diverged_with_its_time():
    scn = load_scenario(None, ["plant.kind=cosserat", "plant.cosserat.elements_per_section=3",
                               "plant.cosserat.shear_factor=10", "control_dt=0.01", "duration=0.3",
                               "interaction_forces=[[0,0],[1000,-1000]]"])
    tr = simulate(scn)
    assert tr.status == "diverged", tr.message
    assert "plant state" in tr.message and "at t = " in tr.message
    assert len(tr) >= 1
