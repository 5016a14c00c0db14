"""The MuJoCo loop with its physics thread (`simulate_mujoco(overlap=True)`: MuJoCo stepped in its two phases
by `harness.loop.native.physics_server`, mj_step1 of each state beside the control step) gives the
serial loop's numbers bit for bit, stops where it stops, and reports the same MuJoCo warnings.  No timing
assertions (the speed is measured by benchmarks/bench_loop.py)."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest

from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import PlantConfig, Scenario
from harness.loop import mujoco_loop
from harness.loop.mujoco_loop import overlap_default, simulate_mujoco

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["duration=0.4", "transient=0", "plant.segments=4"]

CASES = {
    # sensing noise, the default plant
    "paper": ("paper.toml", []),
    # two physics steps per control step and a command delay (its ring buffer)
    "substeps_delay": ("paper.toml", ["plant.physics_dt=0.0005", "plant.actuation_delay=0.003"]),
    # contact sensors (a distance sensor is rewritten by mj_step1), the operator's hand, force sensing
    "contact": ("contact.toml", []),
    # the slave runs away: the loop stops inside a compiled call, after the physics thread's mj_step1
    "runaway": ("paper.toml", ["faults.e2_sign=-1", "duration=1.5"]),
    # the explicit integrator: MuJoCo can split it too
    "euler": ("paper.toml", ["plant.integrator='euler'"]),
    # torque actuation on the CC chain (equality constraints in mj_step1), servo without feed-forward
    "torque_cc": ("paper.toml", ["plant.actuation='torque'", "plant.enforce_cc=true"]),
    "servo_no_feedforward": ("paper.toml", ["plant.servo_feedforward=false"]),
}


def _same(a, b, traj_arrays, what: str) -> None:
    assert (a.status, a.message, len(a)) == (b.status, b.message, len(b)), what
    for key in ("mujoco_warnings", "mujoco_warning_counts", "mujoco_warning_text"):
        assert a.meta[key] == b.meta[key], f"{what}: {key}"
    ra, rb = traj_arrays(a), traj_arrays(b)
    assert ra.keys() == rb.keys(), what
    for key, v in ra.items():
        np.testing.assert_array_equal(rb[key], v, err_msg=f"{what}: {key}")


@pytest.mark.parametrize("case", list(CASES))
def test_physics_thread_gives_the_serial_numbers(case, traj_arrays):
    """Every Trajectory array, the status and message, and MuJoCo's warning report are the same with and
    without the physics thread (three threaded runs: a race would show as a difference between them)."""
    name, sets = CASES[case]
    scn = load_scenario(ROOT / "scenarios" / name, [*SHORT, *sets])
    ref = simulate_mujoco(scn, overlap=False)
    assert ref.meta["overlap"] is False
    if case == "contact":
        assert np.any(ref.F_true != 0.0) and np.any(ref.contact != 0.0)
    if case == "runaway":
        assert ref.status != "ok" and 0 < len(ref) < scn.n_steps, ref.message
    for rep in range(3):
        tr = simulate_mujoco(scn, overlap=True)
        assert tr.meta["overlap"] is True
        _same(ref, tr, traj_arrays, f"{case}, threaded run {rep}")


def test_physics_thread_stops_at_the_warning_step(traj_arrays):
    """MuJoCo's warning (euler, stiff servos: mjWARN_BADQACC, tests/test_reliability.py) stops the threaded
    loop at the same step, with the same counts and MuJoCo text, although its physics thread has already
    run mj_step1 of the next state."""
    plant = PlantConfig(integrator="euler", servo_frequency=160.0, enforce_cc=True,
                        bending_viscosity=(0.0,) * 3, extension_viscosity=(0.0,) * 3)
    scn = Scenario(duration=0.3, plant=plant)
    ref = simulate_mujoco(scn, overlap=False)
    assert ref.status == "diverged" and ref.message.startswith("MuJoCo warning (mjWARN_BADQACC")
    _same(ref, simulate_mujoco(scn, overlap=True), traj_arrays, "warning")


def test_physics_thread_with_any_chunk_boundaries(monkeypatch, traj_arrays):
    """Compiled calls of 1-97 steps in a seeded random order (the physics thread runs on between them)
    give the serial run, and each chunk handed to on_chunk (a live view) already holds its plant geometry
    (copied by the physics thread)."""
    scn = load_scenario(ROOT / "scenarios" / "contact.toml", SHORT)
    ref = simulate_mujoco(scn, overlap=False)
    rng = np.random.default_rng(11)
    monkeypatch.setattr(mujoco_loop, "MUJOCO_CHUNK", 13)
    monkeypatch.setattr(mujoco_loop, "next_chunk", lambda steps, seconds, on_chunk: int(rng.integers(1, 98)))
    parts = []
    _same(ref, simulate_mujoco(scn, overlap=True, on_chunk=parts.append), traj_arrays, "random chunks")
    assert len(parts) > 5
    for key in ("body_pos", "body_quat", "master_pos", "x2_plant"):
        np.testing.assert_array_equal(np.concatenate([getattr(c, key) for c in parts]), getattr(ref, key),
                                      err_msg=key)


def test_the_command_log_replays_the_threaded_run():
    """The [ctrl, qfrc_applied] a threaded run logs are those of the serial run (the raw-MuJoCo replay of
    the benchmarks uses them)."""
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", SHORT)
    m, _, _ = mujoco_loop.make_plant(scn)
    logs = []
    for overlap in (False, True):
        log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
        simulate_mujoco(scn, cmd_log=log, overlap=overlap)
        logs.append(log)
    assert np.any(logs[0] != 0.0)
    np.testing.assert_array_equal(logs[1], logs[0])


def test_no_thread_is_left_behind():
    """The physics thread ends with the run, also when the caller's on_chunk raises."""
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", SHORT)
    before = threading.active_count()
    simulate_mujoco(scn, overlap=True)
    assert threading.active_count() == before

    def boom(part):
        raise RuntimeError("viewer failed")

    with pytest.raises(RuntimeError, match="viewer failed"):
        simulate_mujoco(scn, overlap=True, on_chunk=boom)
    assert threading.active_count() == before
    assert not any(t.name == "mujoco-physics" for t in threading.enumerate())


def test_rk4_cannot_be_split():
    """MuJoCo's mj_step2 integrates RK4 with Euler: overlap=True is refused with the reason, and the default
    keeps RK4 serial."""
    scn = Scenario(duration=0.01, plant=PlantConfig(integrator="rk4"))
    with pytest.raises(ValueError, match=r"overlap=True: .*plant.integrator = 'rk4'"):
        simulate_mujoco(scn, overlap=True)
    assert simulate_mujoco(scn).meta["overlap"] is False


def test_overlap_default_needs_a_free_core(monkeypatch):
    """On by default with 2 CPUs, 3 when work runs beside the loop (teleop run's output imports); never for
    RK4 or interpreted kernels; TELEOP_OVERLAP=0 / 1 forces it."""
    scn = Scenario()
    monkeypatch.delenv("TELEOP_OVERLAP", raising=False)
    monkeypatch.delenv("TELEOP_NO_JIT", raising=False)
    for cpus, beside, want in [(1, False, False), (2, False, True), (2, True, False), (3, True, True)]:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, n=cpus: set(range(n)))
        assert overlap_default(scn, beside=beside) is want, (cpus, beside)
    assert overlap_default(Scenario(plant=PlantConfig(integrator="rk4"))) is False
    monkeypatch.setenv("TELEOP_OVERLAP", "0")
    assert overlap_default(scn) is False
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    monkeypatch.setenv("TELEOP_OVERLAP", "1")
    assert overlap_default(scn) is True
    monkeypatch.setenv("TELEOP_OVERLAP", "yes")
    with pytest.raises(ConfigError, match=r"TELEOP_OVERLAP = 'yes'.*1 \(physics thread on\), 0 \(off\)"):
        overlap_default(scn)
    monkeypatch.setenv("TELEOP_NO_JIT", "1")
    assert overlap_default(scn) is False


def test_sweep_cases_run_serially(monkeypatch):
    """A sweep keeps every core busy with cases: its cases never start a physics thread."""
    import harness.loop
    from harness.studies.executor import run_case

    seen = {}

    def fake_simulate(scn, **kw):
        seen.update(kw)
        raise RuntimeError("stop here")

    monkeypatch.setattr(harness.loop, "simulate", fake_simulate)
    out = run_case({"case_id": "c", "scenario": Scenario(duration=0.01), "metrics": []})
    assert out["status"] == "error" and seen.get("overlap") is False


def test_a_bad_overlap_switch_is_an_input_error(monkeypatch, tmp_path, capsys):
    """`teleop` checks TELEOP_OVERLAP before any command runs: exit 2, one line naming the variable and its
    values, nothing written."""
    from harness.cli import main

    monkeypatch.setenv("TELEOP_OVERLAP", "yes")
    out = tmp_path / "run"
    assert main(["run", "--duration", "0.01", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "TELEOP_OVERLAP = 'yes': 1 (physics thread on), 0 (off), or unset" in err
    assert not out.exists()
