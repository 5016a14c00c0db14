"""Divergence, singularities, interruption and determinism on the real simulator (no stubs)."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from controllers import slave
from controllers.control import slave_control
from controllers.params import Gains, SlaveParams, SubtaskSpec
from harness.config.load import load_scenario
from harness.config.scenario import PlantConfig, Scenario
from harness.loop import common as sim
from harness.loop import simulate
from harness.loop.fast import K
from harness.loop.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
TELEOP = [sys.executable, "-m", "harness.cli"]


def _rerun_verify(path: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("rerun")
    return subprocess.run([str(exe), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_diverging_mujoco_run_keeps_everything(tmp_path):
    """A sign error in the coordination feedback (18) (`faults.e2_sign = -1`) diverges on the default
    plant (finding faults_are_caught): the CLI stops, says when and why, exits 1, and still writes a
    valid recording, metrics and figures of what was computed."""
    out = tmp_path / "div"
    res = subprocess.run([*TELEOP, "run", "--set", "faults.e2_sign=-1", "--duration", "2",
                          "--no-progress", "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                         timeout=600)
    assert res.returncode == 1, res.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "diverged"
    assert " at t = " in metrics["message"]
    assert 0.0 < metrics["sim_time_reached"] < 2.0
    for name in ("run.rrd", "config.toml", "fig2_e1.png", "fig3_e2.png", "fig4_beta.png"):
        assert (out / name).stat().st_size > 0, name
    assert _rerun_verify(out / "run.rrd").returncode == 0
    assert "diverged" in res.stdout + res.stderr


def test_mujoco_warning_stops_the_run_at_the_step_that_raised_it():
    """An explicit integrator with stiff servos (euler, 40 Hz: h kv / M > 2 on the light distal joints,
    whose servo gains are set per unit length of the section) makes MuJoCo raise
    mjWARN_BADQACC within a few ms.  The compiled loop checks MuJoCo's warning counters after every
    mj_step: the run stops at that step (not at the end of a 1000-step chunk), the message names the
    warning and MuJoCo's own text, and the rows up to it are finite."""
    from harness.loop.mujoco_loop import simulate_mujoco

    # the CC chain without material damping (with it, euler's explicit damping blows the state up
    # before MuJoCo's acceleration check fires: a divergence, but not this test's warning)
    scn = Scenario(duration=2.0,
                   plant=PlantConfig(integrator="euler", servo_frequency=40.0, enforce_cc=True,
                                     bending_viscosity=(0.0,) * 3, extension_viscosity=(0.0,) * 3))
    tr = simulate_mujoco(scn)
    assert tr.status == "diverged", tr.message
    assert tr.message.startswith("MuJoCo warning (mjWARN_BADQACC"), tr.message
    assert "MuJoCo says:" in tr.message and f"at t = {tr.t[-1]:.4f} s" in tr.message
    assert tr.meta["mujoco_warnings"] >= 1 and tr.meta["mujoco_warning_counts"]["mjWARN_BADQACC"] >= 1
    assert 1 <= len(tr) < 50  # stopped at the warning, well inside the first compiled chunk
    assert np.all(np.isfinite(tr.q2[:-1])) and np.all(np.isfinite(tr.e2[:-1]))
    # the same model with the implicit integrator (the default) runs through: the warning was real
    ok = simulate_mujoco(Scenario(duration=0.2, plant=PlantConfig(servo_frequency=40.0)))
    assert ok.status == "ok" and ok.meta["mujoco_warnings"] == 0


def test_diverging_analytic_run_reports_time_and_cause():
    """+50 % slave mass on the plant: feedback linearization loses the arm; the partial trajectory is
    returned, finite, and the message names the cause and the time."""
    scn = Scenario(plant=PlantConfig(kind="analytic", slave=SlaveParams(masses=(1.5, 1.05, 0.6))),
                   snr_db=None, duration=5.0)
    tr = simulate(scn)
    assert tr.status == "diverged"
    assert 0 < len(tr) < scn.n_steps
    assert np.all(np.isfinite(tr.q2)) and np.all(np.isfinite(tr.e2))
    assert f"t = {tr.t[-1]:.4f} s" in tr.message
    m = compute_metrics(tr, scn)
    assert m["status"] == "diverged" and m["sim_time_reached"] < 5.0


def test_singular_slave_jacobian_is_detected():
    """J2 J2^T singular (all sections of zero length: only Z can move) stops the law with a clear
    error in the API and status 3 in the compiled loop."""
    q = np.array([1e-9, 1e-9, 1e-9, 0.0, 0.0, 0.0])
    assert np.linalg.det(slave.jacobian(SlaveParams(), q) @ slave.jacobian(SlaveParams(), q).T) < 1e-14
    with pytest.raises(FloatingPointError, match="singular"):
        slave_control(SlaveParams(), Gains(), SubtaskSpec(), q, np.zeros(6), np.array([0.0, 1.0]),
                      np.zeros(2), np.zeros(2))
    a = sim.compile_model(Scenario())._asdict()
    state = np.concatenate([[0.5, 1.1, 0.0, 0.0], q, np.zeros(6)])
    outs = [np.zeros(2), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(10), np.zeros(11)]
    xd = np.array([0.0, 1.0])
    status = K.control_laws(a["mpk_c"], a["spk_c"], a["nodes"], a["weights"], a["gains"], a["spec"], state,
                            xd, np.zeros(2), np.zeros(2), a["F"], *outs)
    from controllers.status import Status

    assert status == Status.SLAVE_SINGULAR
    assert Status(status).text == "slave J2 J2^T singular"


def test_stop_event_interrupts_and_keeps_data():
    """STOP set by another thread while the run is under way (after its second chunk of steps: a fixed
    point, however fast the machine; a 1.5-s timer stopped being early enough once the analytic plant ran
    120 s in under 1.5 s) ends the run there with every step so far."""
    scn = Scenario(plant=PlantConfig(kind="analytic"), duration=120.0)
    sizes = []

    def stop_after_two(part):
        sizes.append(len(part))
        if len(sizes) == 2:
            setter = threading.Thread(target=sim.STOP.set)
            setter.start()
            setter.join()

    sim.STOP.clear()
    try:
        tr = simulate(scn, on_chunk=stop_after_two)
    finally:
        sim.STOP.clear()
    assert tr.status == "interrupted"
    assert len(sizes) == 2 and len(tr) == sum(sizes) < scn.n_steps
    assert tr.message.startswith("interrupted at t = ")
    assert np.all(np.isfinite(tr.e2))


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_leaves_valid_files(tmp_path, sig):
    out = tmp_path / "sig"
    # noise-free: with 40 dB noise the analytic plant leaves its ranges and diverges after ~80 s of
    # simulated time (README, Findings), which a fast machine reaches before the signal
    proc = subprocess.Popen([*TELEOP, "run", "--plant", "analytic", "--snr", "none", "--duration", "600",
                             "--no-progress", "--out", str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 240
        while not (out / "config.toml").exists() and time.time() < deadline:
            time.sleep(0.2)
        time.sleep(3.0)  # let it simulate a while
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "interrupted"
    assert 0.0 < metrics["sim_time_reached"] < 600.0
    assert _rerun_verify(out / "run.rrd").returncode == 0
    assert (out / "fig3_e2.png").stat().st_size > 0


def test_same_seed_bit_identical_in_process_mujoco():
    scn = load_scenario(None, ["duration=0.5", "transient=0.1"])
    a, b = simulate(scn), simulate(scn)
    for f in ("q1", "q2", "e2", "T2", "x2_plant"):
        assert getattr(a, f).tobytes() == getattr(b, f).tobytes(), f


def _metrics_of(out: Path) -> dict:
    m = json.loads((out / "metrics.json").read_text())
    for k in ("wall_time", "realtime_factor"):
        m.pop(k)
    return m


@pytest.mark.slow
def test_same_seed_bit_identical_across_processes(tmp_path):
    """Two separate processes, same config and seed -> identical metrics (every digit); another
    seed -> different."""
    env = dict(os.environ)
    outs = []
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        out = tmp_path / name
        res = subprocess.run([*TELEOP, "run", "--duration", "1", "--seed", str(seed),
                              "--set", "transient=0.2",
                              "--no-progress", "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                             timeout=600, env=env)
        assert res.returncode == 0, res.stderr
        outs.append(_metrics_of(out))
    assert outs[0] == outs[1]
    assert outs[0]["e2_rms"] != outs[2]["e2_rms"]
