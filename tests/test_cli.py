"""`teleop` command line (harness.cli).

The simulation/metrics/recording/plotting back ends are replaced by stubs (monkeypatched onto the real
modules when they import, else onto stand-in modules), so these tests are fast and independent of
MuJoCo; `test_run_with_real_back_ends` runs the real ones end to end on a short analytic run.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import signal
import subprocess
import sys
import threading
import types
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.config.load import load_scenario
from harness.config.scenario import Scenario
from harness.loop.trajectory import ROW_WIDTH, Trajectory

ROOT = Path(__file__).resolve().parents[1]
PAPER_TOML = ROOT / "scenarios" / "paper.toml"
PAPER_BOUNDS = ROOT / "bounds" / "paper_mujoco.toml"

OPTIONS = {
    "run": ["--plant", "--actuation", "--segments", "--duration", "--seed", "--snr", "--set", "--out",
            "--no-progress", "--controller", "--view", "SCENARIO.toml"],
    "check": ["--plant", "--actuation", "--segments", "--duration", "--seed", "--snr", "--set", "--out",
              "--no-progress", "--controller", "--bounds", "SCENARIO.toml"],
    "models": ["--segments", "--out", "--enforce-cc", "--no-enforce-cc", "--actuation", "--set",
               "SCENARIO.toml"],
    "sweep": ["--out", "--workers", "--scheduler", "--no-progress", "--view", "STUDY.toml"],
    "fidelity": ["--segments", "--out", "--no-progress"],
    "controllers": [],
    "cache": ["--prune", "--clear"],
    "findings": ["--table", "--figures", "--no-write", "--list", "NAME"],
    "stability-map": ["--duration", "--predicted", "--out"],
    "stability": ["--at", "--fd-step", "--modes", "--plant", "--actuation", "--set", "--out",
                  "SCENARIO.toml"],
    "margin": ["--bounds", "--param", "--rtol", "--probes", "--pair", "--workers", "--executor",
               "--scheduler", "--out", "--no-progress", "--set", "SCENARIO.toml"],
}


def _module(monkeypatch, name: str) -> types.ModuleType:
    """The real module if it imports, else an empty stand-in registered in sys.modules."""
    try:
        return importlib.import_module(name)
    except ImportError:
        mod = types.ModuleType(name)
        monkeypatch.setitem(sys.modules, name, mod)
        return mod


def make_traj(n: int = 50, status: str = "ok", message: str = "", dt: float = 1e-3) -> Trajectory:
    rows = np.zeros((n, ROW_WIDTH))
    rows[:, 0] = np.arange(n) * dt
    traj = Trajectory.from_rows(rows, status=status, message=message)
    traj.beta[:] = 0.05
    return traj


class Stubs:
    """Records calls; `status`, `metrics` and `simulate_hook` steer the stubbed simulation."""

    def __init__(self) -> None:
        self.status = "ok"
        self.message = ""
        self.metrics = {"e1_rms": 1e-4, "e1_max": 2e-4, "e2_rms": 1e-3, "e2_max": 2e-3,
                        "e2_plant_rms": 1.5e-3, "e2_plant_max": 3e-3, "beta_min": 0.55,
                        "deN_rms": 0.08, "range_violation": 0.0, "mujoco_warnings": 0}
        self.simulate_hook = None
        self.calls: dict[str, list] = {}

    def _log(self, name, *args, **kwargs):
        self.calls.setdefault(name, []).append((args, kwargs))

    def simulate(self, scn, plant=None, progress=False, on_chunk=None, on_running=None):
        self._log("simulate", scn, progress=progress)
        if self.simulate_hook is not None:
            return self.simulate_hook(scn)
        return make_traj(status=self.status, message=self.message)

    def compute_metrics(self, traj, scn):
        self._log("compute_metrics", traj, scn)
        return dict(self.metrics, status=traj.status, message=traj.message, e1_final=np.float64(np.nan))

    def write_recording(self, traj, path):
        self._log("write_recording", traj, path)
        Path(path).write_bytes(b"rrd")
        return Path(path)

    def write_figures(self, traj, out, names=None):  # may run in a forked child: the log stays there
        self._log("write_figures", traj, out)
        if names is not None and "fig2_e1.png" not in names:
            return []
        p = Path(out) / "fig2_e1.png"
        p.write_bytes(b"png")
        return [p]


@pytest.fixture
def stubs(monkeypatch):
    s = Stubs()
    monkeypatch.setattr(_module(monkeypatch, "harness.loop"), "simulate", s.simulate, raising=False)
    sim = _module(monkeypatch, "harness.loop.common")
    if not isinstance(getattr(sim, "STOP", None), threading.Event):
        monkeypatch.setattr(sim, "STOP", threading.Event(), raising=False)
    monkeypatch.setattr(_module(monkeypatch, "harness.loop.metrics"), "compute_metrics", s.compute_metrics,
                        raising=False)
    monkeypatch.setattr(_module(monkeypatch, "harness.output.record"), "write_recording", s.write_recording,
                        raising=False)
    monkeypatch.setattr(_module(monkeypatch, "harness.output.plots"), "write_figures", s.write_figures,
                        raising=False)
    return s


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


# --------------------------------------------------------------------------------------------- help
@pytest.mark.parametrize("command", list(OPTIONS))
def test_help_for_each_command(command, capsys):
    assert main([command, "--help"]) == 0
    out = capsys.readouterr().out
    for opt in OPTIONS[command]:
        assert opt in out, (command, opt)
    assert "Default" in out


def _help_entries(text: str) -> dict[str, str]:
    """{invocation: help text} of every argument an argparse help page lists (two-space indented
    entries, their help to the right or on the more indented lines below)."""
    entries: dict[str, str] = {}
    key = None
    for line in text.splitlines():
        start = re.match(r"^  (\S.*?)(?:\s{2,}(\S.*))?$", line)
        if start:
            key = start.group(1)
            entries[key] = start.group(2) or ""
        elif key is not None and re.match(r"^\s{3,}\S", line):
            entries[key] = (entries[key] + " " + line.strip()).strip()
        else:
            key = None
    return entries


def test_every_option_has_a_help_text(capsys):
    assert main(["--help"]) == 0
    top = capsys.readouterr().out
    commands = re.findall(r"^    (\S+)", top.split("commands:", 1)[1], re.M)
    assert set(commands) == set(OPTIONS)
    no_default = ("--no-progress", "--bounds", "--set")
    for name in commands:
        assert main([name, "--help"]) == 0
        entries = _help_entries(capsys.readouterr().out)
        entries.pop("-h, --help")
        for opt in OPTIONS[name]:  # the page was parsed: every known option has its entry
            assert any(opt in re.split(r"[\s,]+", inv) for inv in entries), (name, opt)
        for invocation, text in entries.items():
            assert len(text) > 20, (name, invocation)
            if invocation.startswith("-") and not invocation.startswith(no_default):
                assert "Default" in text, (name, invocation)


def test_top_level_help_and_no_command(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in OPTIONS:
        assert command in out
    assert main([]) == 2


# --------------------------------------------------------------------------------------------- input errors
def test_missing_scenario_file(stubs, tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "nope.toml" in line
    assert "simulate" not in stubs.calls


@pytest.mark.parametrize(("argv", "needle"), [
    (["--segments", "100"], "plant.segments"),
    (["--segments", "2.5"], "plant.segments"),
    (["--duration", "-1"], "duration"),
    (["--duration", "2", "--set", "transient=3"], "transient"),
    (["--snr", "loud"], "snr_db"),
    (["--seed", "-3"], "seed"),
    (["--set", "gains.k1=0"], "gains.k1"),
    (["--set", "plant.segmnts=3"], "plant.segments"),
    (["--set", "trajectory.center=[0.0, 1.3]"], "trajectory"),
    (["--set", "nonsense"], "key=value"),
    (["--plant", "bullet"], "--plant"),
])
def test_bad_values_exit_2_with_one_line(stubs, tmp_path, capsys, argv, needle):
    assert main(["run", *argv, "--out", str(tmp_path / "o")]) == 2
    assert needle in _one_error_line(capsys.readouterr().err)
    assert "simulate" not in stubs.calls


def test_bad_scenario_file_exit_2(stubs, tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text("[gains]\nk1 = true\n")
    assert main(["run", str(p), "--out", str(tmp_path / "o")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "bad.toml" in line and "gains.k1" in line
    p.write_text("[gains\n")
    assert main(["run", str(p)]) == 2
    assert "invalid TOML" in _one_error_line(capsys.readouterr().err)


def test_unwritable_output_dir(stubs, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["run", "--out", str(blocker / "sub")]) == 2
    assert "--out" in _one_error_line(capsys.readouterr().err)
    assert main(["run", "--out", str(blocker)]) == 2
    assert "not a directory" in _one_error_line(capsys.readouterr().err)
    assert "simulate" not in stubs.calls


def test_empty_out_path_is_rejected(stubs, capsys):
    for cmd in (["run"], ["check", "--bounds", "b.toml"], ["fidelity"], ["models"]):
        assert main([*cmd, "--out", ""]) == 2
        assert "--out" in _one_error_line(capsys.readouterr().err)
    assert "simulate" not in stubs.calls


def test_sweep_output_folder_errors_are_one_line(tmp_path, capsys, monkeypatch):
    """A bad study creates no folder; an unusable output folder (given, or the default one under an
    unwritable working directory) is a one-line error before any case runs."""
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[factorz]]\nparam = "seed"\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "never")]) == 2
    msg = _one_error_line(capsys.readouterr().err)
    assert "'name' belongs under [study]" in msg and "did you mean 'factor'" in msg and str(bad) in msg
    assert not (tmp_path / "never").exists()
    good = tmp_path / "good.toml"
    good.write_text('[study]\nname = "g"\n[[factor]]\nparam = "seed"\nvalues = [0, 1]\n')
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["sweep", str(good), "--out", str(blocker)]) == 2
    assert "--out" in _one_error_line(capsys.readouterr().err)
    cwd = tmp_path / "cwd"  # the default folder runs/sweeps/g cannot be made: 'runs' is a file here
    cwd.mkdir()
    (cwd / "runs").write_text("x")
    monkeypatch.chdir(cwd)
    assert main(["sweep", str(good), "--no-progress"]) == 2
    assert "sweep output folder (default)" in _one_error_line(capsys.readouterr().err)


def test_bad_bounds_file_exit_2(stubs, tmp_path, capsys):
    b = tmp_path / "b.toml"
    b.write_text("[bounds]\ne2_rms_max = -1\n")
    assert main(["check", "--bounds", str(b)]) == 2
    assert "bounds.e2_rms_max" in _one_error_line(capsys.readouterr().err)
    assert main(["check", "--bounds", str(tmp_path / "missing.toml")]) == 2
    assert "simulate" not in stubs.calls


def test_check_requires_bounds(capsys):
    assert main(["check"]) == 2
    assert "--bounds" in _one_error_line(capsys.readouterr().err)


# --------------------------------------------------------------------------------------------- run
def test_run_writes_outputs(stubs, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["run", str(PAPER_TOML), "--plant", "analytic", "--segments", "16", "--snr", "none",
               "--seed", "7", "--duration", "3", "--set", "transient=1",
               "--set", "plant.slave.masses=[1.2,0.7,0.4]", "--out", str(out), "--no-progress"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    (args, kwargs), = stubs.calls["simulate"]
    scn = args[0]
    assert kwargs == {"progress": False}
    assert (scn.plant.kind, scn.plant.segments, scn.snr_db, scn.seed, scn.duration, scn.transient) == (
        "analytic", 16, None, 7, 3.0, 1.0)
    assert scn.plant.slave.masses == (1.2, 0.7, 0.4)
    assert load_scenario(out / "config.toml") == scn
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["e2_rms"] == 1e-3 and metrics["status"] == "ok"
    assert metrics["e1_final"] is None  # NaN -> null (valid JSON)
    assert (out / "run.rrd").exists() and (out / "fig2_e1.png").exists()
    assert "status ok" in captured.out and "e2_rms" in captured.out
    assert captured.err == ""


def test_run_default_out_dir_and_progress(stubs, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--set", 'name="quick"']) == 0
    assert (tmp_path / "runs" / "quick" / "metrics.json").exists()
    assert stubs.calls["simulate"][0][1] == {"progress": True}
    assert stubs.calls["simulate"][0][0][0] == load_scenario({"name": "quick"})


@pytest.mark.parametrize("status", ["diverged", "error"])
def test_run_failure_still_writes_outputs(stubs, tmp_path, capsys, status):
    stubs.status, stubs.message = status, "non-finite state at t = 0.05 s"
    out = tmp_path / "o"
    assert main(["run", "--out", str(out), "--no-progress"]) == 1
    assert json.loads((out / "metrics.json").read_text())["status"] == status
    assert (out / "config.toml").exists() and (out / "run.rrd").exists()
    assert "non-finite state" in _one_error_line(capsys.readouterr().err)


def test_run_output_failure_is_reported(stubs, tmp_path, capsys, monkeypatch):
    def broken(traj, path):
        raise RuntimeError("disk full")

    monkeypatch.setattr(sys.modules["harness.output.record"], "write_recording", broken)
    out = tmp_path / "o"
    assert main(["run", "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "disk full" in err and "Traceback" not in err
    assert (out / "metrics.json").exists() and (out / "fig2_e1.png").exists()


def test_run_metrics_failure_still_writes_status(stubs, tmp_path, monkeypatch):
    def broken(traj, scn):
        raise ValueError("empty trajectory")

    monkeypatch.setattr(sys.modules["harness.loop.metrics"], "compute_metrics", broken)
    out = tmp_path / "o"
    assert main(["run", "--out", str(out), "--no-progress"]) == 1
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["status"] == "ok" and "empty trajectory" in doc["metrics_error"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_the_run_and_writes_outputs(stubs, tmp_path, capsys, sig):
    stop = sys.modules["harness.loop.common"].STOP

    def hook(scn):
        os.kill(os.getpid(), sig)
        assert stop.wait(5.0), "the signal handler did not set harness.loop.common.STOP"
        return make_traj(n=20, status="interrupted", message="interrupted at t = 0.019 s")

    stubs.simulate_hook = hook
    before = signal.getsignal(sig)
    out = tmp_path / "o"
    assert main(["run", "--out", str(out), "--no-progress"]) == 130
    assert signal.getsignal(sig) == before  # handlers restored
    assert not stop.is_set()
    assert json.loads((out / "metrics.json").read_text())["status"] == "interrupted"
    assert (out / "config.toml").exists()
    assert "interrupted" in capsys.readouterr().err


def test_simulation_error_is_an_input_error(stubs, tmp_path, capsys, monkeypatch):
    sim = sys.modules["harness.loop.common"]
    exc = getattr(sim, "SimulationError", None)
    if exc is None:
        exc = type("SimulationError", (RuntimeError,), {})
        monkeypatch.setattr(sim, "SimulationError", exc, raising=False)

    def hook(scn):
        raise exc("initial.master_offset: unreachable")

    stubs.simulate_hook = hook
    assert main(["run", "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert "unreachable" in _one_error_line(capsys.readouterr().err)


# --------------------------------------------------------------------------------------------- check
def _bounds(tmp_path, text="[bounds]\ne1_rms_max = 1e-3\ne2_rms_max = 1e-2\nbeta_min_min = 1e-3\n"):
    p = tmp_path / "b.toml"
    p.write_text(text)
    return p


def test_check_passes(stubs, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["check", "--bounds", str(_bounds(tmp_path)), "--no-progress"]) == 0
    assert "all bounds satisfied" in capsys.readouterr().out
    assert not (tmp_path / "runs").exists()  # no --out: nothing written


def test_check_lists_violations(stubs, tmp_path, capsys):
    stubs.metrics.update(e2_rms=0.0123, beta_min=5e-4)
    out = tmp_path / "o"
    assert main(["check", "--bounds", str(_bounds(tmp_path)), "--out", str(out), "--no-progress"]) == 1
    text = capsys.readouterr().out
    assert "e2_rms = 0.0123 m exceeds limit 0.0100 m" in text
    assert "beta_min = " in text and "is below limit" in text
    assert "e1_rms" not in text.split("violated")[1]
    assert (out / "metrics.json").exists()


def test_check_missing_metric_and_failed_run(stubs, tmp_path, capsys):
    del stubs.metrics["e2_plant_rms"]
    stubs.status = "diverged"
    b = _bounds(tmp_path, "[bounds]\ne2_plant_rms_max = 0.01\nstatus_ok = true\n")
    assert main(["check", "--bounds", str(b), "--no-progress"]) == 1
    text = capsys.readouterr().out
    assert "e2_plant_rms not measured" in text and "status = 'diverged'" in text


def test_check_with_shipped_bounds(stubs, capsys):
    assert main(["check", str(PAPER_TOML), "--bounds", str(PAPER_BOUNDS), "--no-progress"]) == 0, \
        capsys.readouterr()


# --------------------------------------------------------------------------------------------- models
@pytest.fixture
def export_stub(monkeypatch):
    calls = []

    def export_mjcf(master, slave, plant, path):
        calls.append((master, slave, plant, Path(path)))
        Path(path).write_text("<mujoco/>")
        return Path(path)

    monkeypatch.setattr(_module(monkeypatch, "harness.plant.mujoco_model"), "export_mjcf", export_mjcf,
                        raising=False)
    return calls


def test_models_exports_the_plant(export_stub, tmp_path, capsys):
    out = tmp_path / "m" / "model.xml"
    rc = main(["models", "--segments", "16", "--enforce-cc", "--actuation", "torque", "--out", str(out),
               "--set", "plant.slave.masses=[1.2,0.7,0.4]"])
    assert rc == 0
    (master, slave, plant, path), = export_stub
    assert path == out and out.exists()
    assert (plant.segments, plant.enforce_cc, plant.actuation) == (16, True, "torque")
    assert slave.masses == (1.2, 0.7, 0.4)  # the plant slave, not the nominal one
    assert master == Scenario().master
    assert str(out) in capsys.readouterr().out


def test_models_default_path_and_errors(export_stub, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["models", "--segments", "4", "--no-enforce-cc"]) == 0
    assert export_stub[-1][3] == Path("mjcf") / "octarm_servo_n4.xml"
    assert export_stub[-1][2].enforce_cc is False
    assert main(["models", "--segments", "4", "--set", "plant.enforce_cc=true"]) == 0
    assert export_stub[-1][3] == Path("mjcf") / "octarm_servo_n4_cc.xml"
    assert main(["models"]) == 0
    assert export_stub[-1][2] == Scenario().plant
    assert main(["models", "--segments", "65"]) == 2
    assert "plant.segments" in _one_error_line(capsys.readouterr().err)
    assert main(["models", "--out", str(tmp_path)]) == 2  # a directory
    assert "--out" in _one_error_line(capsys.readouterr().err)


def test_models_plant_model_error_exit_2(monkeypatch, tmp_path, capsys):
    mod = _module(monkeypatch, "harness.plant.mujoco_model")
    exc = getattr(mod, "PlantModelError", None)
    if exc is None:
        exc = type("PlantModelError", (ValueError,), {})
        monkeypatch.setattr(mod, "PlantModelError", exc, raising=False)

    def export_mjcf(master, slave, plant, path):
        raise exc("bad MJCF scene.xml: line 3")

    monkeypatch.setattr(mod, "export_mjcf", export_mjcf, raising=False)
    assert main(["models", "--out", str(tmp_path / "x.xml")]) == 2
    assert "bad MJCF" in _one_error_line(capsys.readouterr().err)


# ----------------------------------------------------------------------------------------- sweep / fidelity
def test_sweep_delegates(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(_module(monkeypatch, "harness.studies.sweep"), "main_sweep",
                        lambda *a, **k: calls.append((a, k)) or 0, raising=False)
    study = tmp_path / "study.toml"
    study.write_text("")
    assert main(["sweep", str(study), "--out", str(tmp_path / "s"), "--workers", "3",
                 "--scheduler", "tcp://h:8786", "--no-progress"]) == 0
    none = {"overrides": [], "case_timeout": None}
    assert calls == [((study, tmp_path / "s", 3, "tcp://h:8786", False),
                      {"max_cases": None, "executor": "processes", **none, "allow_code": False})]
    assert main(["sweep", str(study)]) == 0
    assert calls[-1] == ((study, None, None, None, True),
                         {"max_cases": None, "executor": "processes", **none, "allow_code": False})
    assert main(["sweep", str(study), "--executor", "threads", "--max-cases", "5"]) == 0
    assert calls[-1] == ((study, None, None, None, True),
                         {"max_cases": 5, "executor": "threads", **none, "allow_code": False})
    assert main(["sweep", str(study), "--set", "duration=2", "--set", "seed=3", "--case-timeout", "1.5"]) == 0
    assert calls[-1][1]["overrides"] == ["duration=2", "seed=3"] and calls[-1][1]["case_timeout"] == 1.5


def test_sweep_errors(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(_module(monkeypatch, "harness.studies.sweep"), "main_sweep", lambda *a, **k: 0,
                        raising=False)
    assert main(["sweep", str(tmp_path / "missing.toml")]) == 2
    assert "missing.toml" in _one_error_line(capsys.readouterr().err)
    study = tmp_path / "study.toml"
    study.write_text("")
    assert main(["sweep", str(study), "--workers", "0"]) == 2
    assert "--workers" in _one_error_line(capsys.readouterr().err)


def test_fidelity_delegates(monkeypatch, tmp_path, capsys):
    calls = []
    monkeypatch.setattr(_module(monkeypatch, "harness.studies.fidelity"), "main_fidelity",
                        lambda *a: calls.append(a) or 0, raising=False)
    assert main(["fidelity", "--segments", "2, 4,8", "--out", str(tmp_path / "f")]) == 0
    assert calls == [([2, 4, 8], tmp_path / "f", True, 50, 0)]
    for bad in ("4,x", "0,4", "4,4", "65", ""):
        assert main(["fidelity", "--segments", bad, "--out", str(tmp_path / "f")]) == 2
        assert "--segments" in _one_error_line(capsys.readouterr().err)


# --------------------------------------------------------------------------------------------- processes
@pytest.mark.slow
def test_console_entry_point_error_is_one_line(tmp_path):
    res = subprocess.run([sys.executable, "-m", "harness.cli", "run", "--segments", "0",
                          "--out", str(tmp_path / "o")], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert res.returncode == 2
    assert _one_error_line(res.stderr).startswith("error: plant.segments = 0")


@pytest.mark.slow
def test_run_with_real_back_ends(tmp_path):
    """Short analytic run through the real simulate/metrics/record/plots."""
    out = tmp_path / "real"
    rc = main(["run", "--plant", "analytic", "--duration", "0.05", "--set", "transient=0", "--out", str(out),
               "--no-progress"])
    assert rc == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "ok" and metrics["e1_rms"] is not None
    assert load_scenario(out / "config.toml").duration == 0.05
    assert (out / "run.rrd").stat().st_size > 0


def test_version_is_printed_and_exits_zero(capsys):
    """--version prints "teleop <installed version>" on stdout and exits 0 (looked up only when asked)."""
    from importlib.metadata import version

    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"teleop {version('octarm-teleop')}\n"


@pytest.mark.slow
@pytest.mark.parametrize("preset", [None, "egl"])
def test_prepare_process_turns_mujoco_gl_off_unless_set(preset):
    """`teleop` (entry -> prepare_process) sets MUJOCO_GL=disable only when the user has not set it, so
    `import mujoco` skips the GLFW lookup; and applies the collector thresholds.  In a fresh interpreter,
    because both are process-wide."""
    from harness.config.runtime import GC_THRESHOLDS

    code = ("import gc, os, sys; import harness.cli as cli; cli.prepare_process(); "
            "print(os.environ.get('MUJOCO_GL')); print(list(gc.get_threshold())); "
            "print('mujoco' in sys.modules)")
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    if preset is not None:
        env["MUJOCO_GL"] = preset
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         check=True).stdout.split("\n")
    assert out[0] == (preset or "disable")
    assert json.loads(out[1]) == list(GC_THRESHOLDS)
    assert out[2] == "False"  # importing the CLI does not import MuJoCo: the setting still applies


# ---------------------------------------------------------------------------------------------
# teleop cache: list, prune, clear the compiled-kernel cache
# ---------------------------------------------------------------------------------------------
def _fake_cache(root: Path) -> dict[str, Path]:
    from harness.loop import aot, fast

    names = {"numba_now": f"numba-{fast.source_digest()}", "aot_now": aot.aot_dir().name,
             "numba_old": "numba-0123456789abcdef", "aot_old": "aot-0123456789abcdef-01234567",
             "aot_other_cpu": f"aot-{fast.source_digest()}-ffffffff"}
    paths = {}
    for key, name in names.items():
        p = root / name
        (p / "sub").mkdir(parents=True)
        (p / "sub" / "blob.bin").write_bytes(b"x" * 3000)
        paths[key] = p
    for other in ("notes.txt", "numba-not-a-digest", "mine"):  # not ours: never listed nor removed
        q = root / other
        q.mkdir() if other != "notes.txt" else q.write_text("keep")
        paths[other] = q
    return paths


def test_cache_lists_prunes_and_clears_only_its_folders(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TELEOP_CACHE_DIR", str(tmp_path / "kc"))
    assert main(["cache"]) == 0
    assert "no compiled kernels yet" in capsys.readouterr().out
    paths = _fake_cache(tmp_path / "kc")
    assert main(["cache"]) == 0
    out = capsys.readouterr().out
    for key in ("numba_now", "aot_now"):
        assert f"current  {paths[key].name}" in out
    for key in ("numba_old", "aot_old", "aot_other_cpu"):
        assert f"stale    {paths[key].name}" in out
    assert "5 folder(s)" in out and "3 stale" in out
    assert "notes.txt" not in out and "mine" not in out and "numba-not-a-digest" not in out

    assert main(["cache", "--prune"]) == 0
    assert "removed 3 of 5 folder(s)" in capsys.readouterr().out
    assert all(paths[k].exists() for k in ("numba_now", "aot_now", "notes.txt", "mine", "numba-not-a-digest"))
    assert not any(paths[k].exists() for k in ("numba_old", "aot_old", "aot_other_cpu"))

    assert main(["cache", "--clear"]) == 0
    assert "removed 2 of 2 folder(s)" in capsys.readouterr().out
    assert not paths["numba_now"].exists() and not paths["aot_now"].exists()
    assert all(paths[k].exists() for k in ("notes.txt", "mine", "numba-not-a-digest"))


def test_cache_options_and_a_root_that_is_a_file(tmp_path, monkeypatch, capsys):
    assert main(["cache", "--prune", "--clear"]) == 2  # one or the other
    assert "not allowed with argument" in capsys.readouterr().err
    root = tmp_path / "file"
    root.write_text("")
    monkeypatch.setenv("TELEOP_CACHE_DIR", str(root))
    assert main(["cache"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "is not a folder" in err and "Traceback" not in err


def test_cache_reports_a_folder_it_cannot_remove(tmp_path, monkeypatch, capsys):
    from harness.loop import cache_admin

    monkeypatch.setenv("TELEOP_CACHE_DIR", str(tmp_path / "kc"))
    paths = _fake_cache(tmp_path / "kc")

    def refuse(path, *a, **k):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(cache_admin.shutil, "rmtree", refuse)
    assert main(["cache", "--prune"]) == 1
    cap = capsys.readouterr()
    assert cap.err.count("could not remove") == 3 and "Permission denied" in cap.err
    assert "removed 0 of 5 folder(s), 0.0 MiB freed" in cap.out
    assert paths["numba_old"].exists()


def test_stability_map_command_writes_its_table_and_figure(tmp_path, monkeypatch, capsys):
    """`teleop stability-map` runs the grid (cut here to one cell of one map, 0.05 s) and writes the table and
    the figure; a bad --duration is one usage line."""
    from harness.studies import stability_map as smap

    monkeypatch.setattr(smap, "KNS", (10.0,))
    monkeypatch.setattr(smap, "ETAS", (0.01,))
    monkeypatch.setattr(smap, "MAPS", dict(list(smap.MAPS.items())[:1]))
    out = tmp_path / "smap"
    assert main(["stability-map", "--duration", "0.05", "--out", str(out)]) == 0
    assert (out / "stability_map.png").stat().st_size > 0
    assert "| 10" in (out / "stability_map.md").read_text() or "10" in (out / "stability_map.md").read_text()
    assert main(["stability-map", "--duration", "0"]) == 2
    assert "expected a positive number" in capsys.readouterr().err


def test_stability_map_predicted_sits_next_to_the_simulated_map(tmp_path, monkeypatch):
    """`teleop stability-map --predicted` (one cell: k_n = 100, eta_b = 0.001, 0.5 s): the linearization
    calls the cell unstable (a flip) and its simulation diverges, in one table cell."""
    from harness.studies import stability_map as smap

    monkeypatch.setattr(smap, "KNS", (100.0,))
    monkeypatch.setattr(smap, "ETAS", (0.001,))
    monkeypatch.setattr(smap, "MAPS", {smap.PREDICTED: smap.MAPS[smap.PREDICTED]})
    out = tmp_path / "smap"
    assert main(["stability-map", "--duration", "0.5", "--predicted", "--out", str(out)]) == 0
    text = (out / "stability_map.md").read_text()
    assert "predicted" in text
    cell = text.splitlines()[-1]
    assert "(unstable, flip) / sim: diverged" in cell, cell


def test_run_summary_units_come_from_the_metric_table():
    """The summary prints each metric's unit from harness.config.metrics (none for beta_min and the
    warning count) and skips what was not measured."""
    from harness.cli import _SUMMARY_KEYS, _summary_items
    from harness.config.metrics import METRIC_UNITS

    assert [k for k in _SUMMARY_KEYS if k not in METRIC_UNITS] == []
    metrics = {"e1_rms": 1.5e-5, "e2_rms": 0.0123, "e2_plant_rms": float("nan"), "e2_plant_max": None,
               "beta_min": 0.5, "mujoco_warnings": 2}
    assert _summary_items(metrics) == ["e1_rms = 1.500e-05 m", "e2_rms = 0.0123 m", "beta_min = 0.5",
                                       "mujoco_warnings = 2"]
