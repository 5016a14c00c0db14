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
from harness.loop.mujoco_loop import AFTER_BESIDE, AUTO, SERIAL, THREADED, overlap_plan, simulate_mujoco

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
    scn = _warning_scenario()
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


def test_overlap_plan_needs_a_free_core(monkeypatch):
    """By default the physics thread may take over (after a comparison) with 2 CPUs, with 2 CPUs and work
    beside the loop (teleop run's output imports) only after that work, never with 1 CPU, RK4 or interpreted
    kernels; TELEOP_OVERLAP=0 / 1 forces it off / on from the first step."""
    scn = Scenario()
    monkeypatch.delenv("TELEOP_OVERLAP", raising=False)
    monkeypatch.delenv("TELEOP_NO_JIT", raising=False)
    for cpus, beside, want in [(1, False, SERIAL), (1, True, SERIAL), (2, False, AUTO),
                               (2, True, AFTER_BESIDE), (3, True, AUTO)]:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, n=cpus: set(range(n)))
        assert overlap_plan(scn, beside=beside) == want, (cpus, beside)
    assert overlap_plan(Scenario(plant=PlantConfig(integrator="rk4"))) == SERIAL
    monkeypatch.setenv("TELEOP_OVERLAP", "0")
    assert overlap_plan(scn) == SERIAL
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    monkeypatch.setenv("TELEOP_OVERLAP", "1")
    assert overlap_plan(scn) == THREADED
    monkeypatch.setenv("TELEOP_OVERLAP", "yes")
    with pytest.raises(ConfigError, match=r"TELEOP_OVERLAP = 'yes'.*1 \(physics thread on\), 0 \(off\)"):
        overlap_plan(scn)
    monkeypatch.setenv("TELEOP_NO_JIT", "1")
    assert overlap_plan(scn) == SERIAL


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


def _warning_scenario() -> Scenario:
    plant = PlantConfig(integrator="euler", servo_frequency=40.0, enforce_cc=True,
                        bending_viscosity=(0.0,) * 3, extension_viscosity=(0.0,) * 3)
    return Scenario(duration=0.3, plant=plant)


@pytest.mark.parametrize("case", ["paper", "substeps_delay", "contact", "runaway", "torque_cc", "warning"])
def test_the_physics_thread_starts_and_stops_at_any_step(case, monkeypatch, traj_arrays):
    """The loop hands MuJoCo's stepping to the physics thread and back between compiled calls (the default
    on 2 CPUs once the output imports end, `overlap_plan`; back when the thread is slower): switched at
    random after compiled calls of 1-97 steps, both ways, a run gives the serial run's numbers, sensors
    (a contact distance sensor is rewritten by the thread's mj_step1) and warnings included."""
    if case == "warning":
        scn = _warning_scenario()
    else:
        name, sets = CASES[case]
        scn = load_scenario(ROOT / "scenarios" / name, [*SHORT, *sets])
    ref = simulate_mujoco(scn, overlap=False)
    if case == "warning":
        assert ref.status == "diverged" and ref.meta["mujoco_warning_text"], ref.message
    rng = np.random.default_rng(sum(map(ord, case)))
    monkeypatch.setattr(mujoco_loop, "MUJOCO_CHUNK", 13)
    monkeypatch.setattr(mujoco_loop, "next_chunk", lambda steps, seconds, on_chunk: int(rng.integers(1, 98)))
    count = mujoco_loop._Stepping.count
    switches = []

    def switching_count(self, steps):
        count(self, steps)
        self.k = getattr(self, "k", 0) + steps
        if rng.random() < 0.5:
            switches.append(self.threaded)
            if self.threaded:
                self.stop()
            else:
                self.start(self.k)

    monkeypatch.setattr(mujoco_loop._Stepping, "count", switching_count)
    for rep in range(2):
        switches.clear()
        tr = simulate_mujoco(scn, overlap=False)
        _same(ref, tr, traj_arrays, f"{case}, switched run {rep}")
        if len(ref) > 60:
            assert switches.count(False) >= 2 and switches.count(True) >= 2, switches
            assert tr.meta["overlap"] is True and 0 < tr.meta["overlap_steps"] < len(tr)


class _SlowCalls:
    """Stands for harness.loop.aot.A in the MuJoCo loop: counts the compiled calls, ends the work `beside`
    the loop after `serial_calls` of them, and makes every threaded call (`slow` = "threaded") or every serial
    one ("serial") 0.05 s slower, so that the loop's comparison of the two has a known answer."""

    def __init__(self, serial_calls: int, slow: str):
        from harness.loop.aot import A

        self.real, self.serial_calls, self.slow = A, serial_calls, slow
        self.calls = 0
        self.release = threading.Event()
        self.beside = threading.Thread(target=self.release.wait, name="beside-work")
        self.modes: list[bool] = []

    def __getattr__(self, name):
        return getattr(self.real, name)

    def mujoco_chunk(self, *args):
        threaded = args[-1].shape[0] > 0
        if args[3] != args[4]:  # a call with steps (not the kernel-loading call)
            self.modes.append(threaded)
            self.calls += 1
            if threaded == (self.slow == "threaded"):
                import time

                time.sleep(0.05)
            if self.calls == self.serial_calls:
                self.release.set()
                self.beside.join()
        return self.real.mujoco_chunk(*args)

    def on_running(self):
        self.beside.start()
        return self.beside


@pytest.mark.parametrize("slow", ["serial", "threaded"])
@pytest.mark.parametrize("beside", [True, False], ids=["after_beside", "auto"])
def test_the_physics_thread_takes_over_when_a_core_is_free_if_faster(beside, slow, monkeypatch, traj_arrays):
    """With 2 CPUs the loop's thread steps MuJoCo first: with work beside the loop (teleop run's output
    imports, whose thread on_running returns) until that work ends; else for three calls (the first starts
    cold, the others are the reference).  Then the physics thread takes over, for good unless its first call
    is slower per step than the serial ones (made slower on purpose here): then only for that call.  The
    numbers are the serial run's."""
    monkeypatch.delenv("TELEOP_OVERLAP", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", ["duration=1.0", "transient=0"])
    ref = simulate_mujoco(scn, overlap=False)
    monkeypatch.setattr(mujoco_loop, "MUJOCO_CHUNK" if beside else "PROBE_CALL", 50)
    serial = 4 if beside else 3
    fake = _SlowCalls(serial_calls=serial if beside else 0, slow=slow)
    monkeypatch.setattr(mujoco_loop, "A", fake)
    tr = simulate_mujoco(scn, on_running=fake.on_running if beside else None)
    _same(ref, tr, traj_arrays, f"beside {beside}, slow {slow}")
    assert fake.modes[:serial + 1] == [False] * serial + [True], fake.modes
    assert tr.meta["overlap_from_step"] == serial * 50
    if slow == "threaded":  # one threaded call of PROBE_CHUNKS * 50 steps, then serial to the end
        assert not any(fake.modes[serial + 1:]) and len(fake.modes) > serial + 1, fake.modes
        assert tr.meta["overlap_steps"] == mujoco_loop.PROBE_CHUNKS * 50
    else:
        assert all(fake.modes[serial:]), fake.modes
        assert tr.meta["overlap_steps"] == len(tr) - serial * 50


def test_without_a_handle_on_the_work_beside_the_loop_stays_serial(monkeypatch):
    """On 2 CPUs, an on_running that returns no thread: the loop cannot know when a core frees up, and never
    starts its physics thread."""
    monkeypatch.delenv("TELEOP_OVERLAP", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", SHORT)
    tr = simulate_mujoco(scn, on_running=lambda: None)
    assert tr.meta["overlap"] is False and tr.meta["overlap_from_step"] is None
