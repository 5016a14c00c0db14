"""User controllers cannot end the process, pass silently, block the harness or run from files without
the user's say-so: every failure of a controller's code is one line naming the controller and the phase
(exit 1, status "error"), a real Ctrl-C still interrupts (exit 130), actions are checked for shape, dtype
and finiteness, a missing method is refused before anything runs, a per-step time limit stops a blocking
controller, and code named in a scenario, study or replayed config.toml runs only with --allow-code."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from harness.api import load_scenario
from harness.cli import main
from harness.config.errors import ConfigError
from harness.loop import simulate

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["duration=0.05", "transient=0.0"]

CONTROLLERS = textwrap.dedent('''
    import os
    import sys
    import time

    import numpy as np

    from controllers.baselines import BUILTINS
    from controllers.interface import Action, Controller

    Base = BUILTINS["dls_ik"]  # runs on the default plant (MuJoCo, servo)


    class StepRaises(Base):
        what = None

        def step(self, obs):
            if obs.k == 5:
                raise self.what
            return super().step(obs)


    class StepExit0(StepRaises):
        what = SystemExit(0)


    class StepKeyboard(StepRaises):
        what = KeyboardInterrupt()


    class ResetExit(Base):
        def reset(self, ctx):
            sys.exit(3)


    class InitRaises(Base):
        def __init__(self):
            raise RuntimeError("no licence")


    class InitExit(Base):
        def __init__(self):
            raise SystemExit(0)


    class BadCheck(Base):
        from dataclasses import dataclass

        @dataclass(frozen=True)
        class Params:
            gain: float = 1.0

            def check(self):
                raise SystemExit(0)


    class Field(Base):
        field, value = None, None

        def step(self, obs):
            a = super().step(obs)
            setattr(a, self.field, self.value)
            return a


    class ComplexU2(Field):
        field, value = "u2", np.zeros(6, dtype=complex)


    class StringT2(Field):
        field, value = "T2", np.array(["a"] * 6)


    class ObjectT1(Field):
        field, value = "T1", np.array([object(), object()])


    class Blocks(Base):
        def step(self, obs):
            if obs.k == 3:
                open(os.path.join(os.path.dirname(__file__), "blocking"), "w").close()  # it blocks now
                time.sleep(600)
            return super().step(obs)


    class NoStep(Controller):
        actuations = ("servo", "torque")


    class Plain:
        """Written from the interface's description only: reset(ctx), step(obs) -> Action."""

        def reset(self, ctx):
            self.action = Action()
            self.q0 = ctx.q0[4:10].copy()

        def step(self, obs):
            self.action.u2[:] = -25.0 * (obs.q2 - self.q0) - 10.0 * obs.dq2
            return self.action
''')


@pytest.fixture()
def ctl(tmp_path):
    p = tmp_path / "ctl.py"
    p.write_text(CONTROLLERS)
    return p


def _run(capsys, name, out=None, *extra):
    argv = ["run", "--controller", name, "--no-progress", *[a for s in SHORT for a in ("--set", s)], *extra]
    if out is not None:
        argv += ["--out", str(out)]
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return rc, err


# ------------------------------------------------------------------- 1, 2: nothing ends the process
@pytest.mark.parametrize("cls, text", [
    ("StepExit0", "raised SystemExit(0) at step 5 (t = 0.005 s)"),
    ("StepKeyboard", "raised KeyboardInterrupt at step 5 (t = 0.005 s)"),
    ("ResetExit", "raised SystemExit(3) in reset"),
    ("InitExit", "raised SystemExit(0) in construction"),
    ("InitRaises", "raised RuntimeError: no licence in construction"),
])
def test_controller_code_ending_the_process_is_a_run_error(ctl, tmp_path, capsys, cls, text):
    out = tmp_path / "o"
    rc, err = _run(capsys, f"{ctl}:{cls}", out)
    assert rc == 1, err
    assert len(err) == 1 and text in err[0] and repr(f"{ctl}:{cls}") in err[0] and "Traceback" not in err[0]
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["status"] == "error" and text in doc["message"]


def test_check_with_a_controller_that_exits_does_not_pass(ctl, tmp_path, capsys):
    bounds = tmp_path / "b.toml"
    bounds.write_text("[bounds]\nstatus_ok = false\n")  # bounds accepting any status: an error still fails
    rc = main(["check", "--controller", f"{ctl}:StepExit0", "--bounds", str(bounds), "--no-progress",
               *[a for s in SHORT for a in ("--set", s)]])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "raised SystemExit(0) at step 5" in err[0]


@pytest.mark.parametrize("code, text", [
    ("import sys\nsys.exit(0)\n", "raised SystemExit(0)"),
    ("raise SystemExit(3)\n", "raised SystemExit(3)"),
    ("raise KeyboardInterrupt\n", "raised KeyboardInterrupt"),
])
def test_exit_at_import_is_one_line_exit_1(tmp_path, capsys, code, text):
    src = tmp_path / "exits.py"
    src.write_text(code)
    out = tmp_path / "never"
    rc, err = _run(capsys, f"{src}:C", out)
    assert rc == 1 and len(err) == 1 and text in err[0] and "importing" in err[0]
    assert not out.exists()


def test_params_check_raising_is_one_line_naming_the_phase(ctl, tmp_path, capsys):
    rc, err = _run(capsys, f"{ctl}:BadCheck", tmp_path / "never")
    assert rc == 1 and len(err) == 1 and "raised SystemExit(0) in its Params check" in err[0]
    assert not (tmp_path / "never").exists()


# ------------------------------------------------------------------- 3: actions
@pytest.mark.parametrize("cls, text", [
    ("ComplexU2", "returned u2 of dtype complex128 (expected real floating-point numbers) at step 0"),
    ("StringT2", "returned T2 of dtype <U1"),
    ("ObjectT1", "returned T1 of dtype object"),
])
def test_actions_of_the_wrong_dtype_are_refused_naming_the_field(ctl, cls, text):
    name = f"{ctl}:{cls}"
    tr = simulate(load_scenario(None, [*SHORT, f'controller.name="{name}"']))
    assert tr.status == "error" and text in tr.message and repr(name) in tr.message, tr.message
    assert len(tr) == 0 and "\n" not in tr.message


# ------------------------------------------------------------------- 4: the protocol
def test_a_subclass_without_step_is_refused_before_anything_runs(ctl, tmp_path, capsys):
    with pytest.raises(ConfigError, match="no method step"):
        load_scenario(None, [f'controller.name="{ctl}:NoStep"'])
    rc, err = _run(capsys, f"{ctl}:NoStep", tmp_path / "never")
    assert rc == 2 and len(err) == 1 and "no method step" in err[0] and not (tmp_path / "never").exists()


def test_a_plain_class_written_from_the_description_runs(ctl, tmp_path, capsys):
    rc, err = _run(capsys, f"{ctl}:Plain", tmp_path / "o")
    assert rc == 0, err
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["status"] == "ok"
    with pytest.raises(ConfigError, match="takes no parameters"):
        load_scenario(None, [f'controller.name="{ctl}:Plain"', "controller.params.gain=1"])


# ------------------------------------------------------------------- 5: time limit, Ctrl-C
def test_a_blocking_controller_is_stopped_by_the_step_time_limit(ctl):
    scn = load_scenario(None, [*SHORT, f'controller.name="{ctl}:Blocks"', "controller.step_timeout=0.3"])
    t0 = time.monotonic()
    tr = simulate(scn)
    assert time.monotonic() - t0 < 60
    assert tr.status == "error" and len(tr) == 3
    assert "ran longer than controller.step_timeout = 0.3 s at step 3 (t = 0.003 s)" in tr.message


@pytest.mark.parametrize("value, ok", [("none", None), ("2.5", 2.5), ("-1", False), ("0", False),
                                       ('"x"', False), ("true", False)])
def test_step_timeout_is_validated_and_written_to_config(tmp_path, value, ok):
    if ok is False:
        with pytest.raises(ConfigError,
                           match=r"controller.step_timeout = .*: must be a number in \(0, 86400\]"):
            load_scenario(None, [f"controller.step_timeout={value}"])
        return
    from harness.config.load import dump_scenario
    from harness.config.load import load_scenario as load_file

    scn = load_scenario(None, [f"controller.step_timeout={value}"])
    assert scn.controller.step_timeout == ok
    dump_scenario(scn, tmp_path / "c.toml")
    assert load_file(tmp_path / "c.toml").controller.step_timeout == ok


def _env():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.setdefault("TELEOP_CACHE_DIR", str(ROOT / ".cache-kernels"))
    return env


@pytest.mark.slow
def test_one_ctrl_c_interrupts_a_blocking_controller(ctl, tmp_path):
    """A real Ctrl-C (SIGINT to the process) while the controller blocks ends the run at once: status
    "interrupted", exit 130, after ONE signal; the controller's own KeyboardInterrupt is an error (above)."""
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "harness.cli", "run", "--controller", f"{ctl}:Blocks",
                             "--duration", "0.05", "--set", "transient=0", "--set",
                             "controller.step_timeout=none", "--no-progress", "--out", str(out)],
                            cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 240  # a cold kernel cache compiles first
    marker = ctl.parent / "blocking"  # written by Blocks beside its file when step 3 starts blocking
    while proc.poll() is None and not marker.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert proc.poll() is None and marker.exists(), "the controller never reached step 3"
    time.sleep(0.5)  # in step 3's sleep
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("one Ctrl-C did not stop a blocking controller")
    assert proc.returncode == 130, err
    assert json.loads((out / "metrics.json").read_text())["status"] == "interrupted"


# ------------------------------------------------------------------- 6: paths with spaces
def test_a_controller_path_with_a_space_works(tmp_path, capsys):
    folder = tmp_path / "my dir"
    folder.mkdir()
    (folder / "ctrl.py").write_text(CONTROLLERS)
    rc, err = _run(capsys, f"{folder / 'ctrl.py'}:Plain", tmp_path / "o")
    assert rc == 0, err


# ------------------------------------------------------------------- 7: files run no code unless allowed
MARKER = textwrap.dedent('''
    from pathlib import Path

    Path(__file__).with_name("IMPORTED").write_text("code ran")
    from controllers.baselines import BUILTINS

    Ctl = BUILTINS["dls_ik"]
''')


@pytest.fixture()
def planted(tmp_path):
    """A scenario file naming a controller file next to it (relative path) that leaves a marker when
    imported; the commands run from another folder."""
    d = tmp_path / "from_elsewhere"
    d.mkdir()
    (d / "ctl.py").write_text(MARKER)
    (d / "scn.toml").write_text('duration = 0.05\ntransient = 0.0\n[controller]\nname = "ctl.py:Ctl"\n')
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    return d, cwd


@pytest.mark.parametrize("command", ["run", "check"])
def test_a_scenario_file_naming_code_is_refused_without_allow_code(planted, capsys, monkeypatch, command):
    d, cwd = planted
    monkeypatch.chdir(cwd)
    extra = ["--bounds", str(ROOT / "bounds" / "paper_mujoco.toml")] if command == "check" else ["--out", "o"]
    rc = main([command, str(d / "scn.toml"), "--no-progress", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--allow-code" in err[0] and "is Python code" in err[0], err
    assert not (d / "IMPORTED").exists() and not (cwd / "o").exists()


def test_allow_code_runs_it_with_the_path_relative_to_the_file(planted, capsys, monkeypatch):
    d, cwd = planted
    monkeypatch.chdir(cwd)
    assert main(["run", str(d / "scn.toml"), "--allow-code", "--no-progress", "--out", "o"]) == 0
    assert (d / "IMPORTED").exists()
    import tomllib

    cfg = tomllib.loads((cwd / "o" / "config.toml").read_text())
    assert cfg["controller"]["name"] == f"{d / 'ctl.py'}:Ctl"


def test_a_module_reference_in_a_file_is_refused_too(tmp_path):
    f = tmp_path / "m.toml"
    f.write_text('[controller]\nname = "os:getcwd"\n')
    with pytest.raises(ConfigError, match="is Python code.*--allow-code"):
        load_scenario(f)


def test_the_command_line_and_the_api_say_so(planted, capsys, monkeypatch):
    d, cwd = planted
    monkeypatch.chdir(cwd)
    assert main(["run", "--controller", str(d / "ctl.py") + ":Ctl", "--no-progress", "--out", "o",
                 *[a for s in SHORT for a in ("--set", s)]]) == 0
    with pytest.raises(ConfigError, match="--allow-code"):
        load_scenario(d / "scn.toml")
    assert load_scenario(d / "scn.toml", allow_code=True).controller.name == f"{d / 'ctl.py'}:Ctl"
    import harness

    assert harness.run(d / "scn.toml", allow_code=True).status == "ok"


def test_a_replayed_config_toml_naming_code_needs_allow_code(ctl, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert _run(capsys, "ctl.py:Plain", tmp_path / "o")[0] == 0
    rc = main(["run", str(tmp_path / "o" / "config.toml"), "--no-progress", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--allow-code" in err[0]
    monkeypatch.chdir(ROOT)  # the recorded path is absolute: the replay works from anywhere
    assert main(["run", str(tmp_path / "o" / "config.toml"), "--allow-code", "--no-progress",
                 "--out", str(tmp_path / "r")]) == 0


def test_teleop_models_never_imports_a_controller(planted, capsys, monkeypatch):
    d, cwd = planted
    monkeypatch.chdir(cwd)
    assert main(["models", str(d / "scn.toml"), "--out", "m.xml"]) == 0
    assert (cwd / "m.xml").is_file() and not (d / "IMPORTED").exists()


def _study(folder: Path, values: list[str]) -> Path:
    (folder / "ctl.py").write_text(CONTROLLERS)
    p = folder / "study.toml"
    p.write_text(textwrap.dedent(f'''
        [study]
        name = "ctl"
        set = ["duration=0.05", "transient=0.0", "controller.step_timeout=0.3"]
        metrics = ["e2_rms"]
        [[factor]]
        param = "controller"
        values = {json.dumps(values)}
        [[factor]]
        param = "seed"
        values = [0, 1]
    '''))
    return p


def test_a_study_naming_code_is_refused_without_allow_code(tmp_path, capsys, monkeypatch):
    d = tmp_path / "s"
    d.mkdir()
    study = _study(d, ["dls_ik", "ctl.py:Plain"])
    monkeypatch.chdir(tmp_path)
    rc = main(["sweep", str(study), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--allow-code" in err[0] and not (tmp_path / "o").exists()


def test_a_failing_controller_in_a_sweep_is_an_error_row_and_the_others_run(tmp_path, capsys, monkeypatch):
    """Controller paths resolve against the study file (run from another folder); the controllers that
    raise SystemExit or block give error rows, the others ok rows; the sweep completes (exit 0)."""
    d = tmp_path / "s"
    d.mkdir()
    study = _study(d, ["dls_ik", "ctl.py:StepExit0", "ctl.py:Plain", "ctl.py:Blocks"])
    monkeypatch.chdir(tmp_path)
    rc = main(["sweep", str(study), "--out", str(tmp_path / "o"), "--no-progress", "--allow-code",
               "--workers", "1"])
    assert rc == 0, capsys.readouterr().err
    rows = [json.loads(line) for line in (tmp_path / "o" / "results.jsonl").read_text().splitlines()]
    by = {(r["params"]["controller"], r["params"]["seed"]): r for r in rows}
    assert len(rows) == 8
    for seed in (0, 1):
        blocked = by[("ctl.py:Blocks", seed)]
        assert blocked["status"] == "error"
        assert "ran longer than controller.step_timeout = 0.3 s at step 3" in blocked["message"]
        assert by[("ctl.py:StepExit0", seed)]["status"] == "error"
        assert "raised SystemExit(0) at step 5" in by[("ctl.py:StepExit0", seed)]["message"]
        assert by[("dls_ik", seed)]["status"] == "ok" and by[("ctl.py:Plain", seed)]["status"] == "ok"


# ------------------------------------------------------------------- 8: hints for known failures
def _diverged(*over):
    from types import SimpleNamespace

    return load_scenario(None, ['plant.actuation="torque"', *over]), SimpleNamespace(status="diverged")


def test_the_torque_hint_names_only_settings_that_differ_from_the_run():
    from harness.cli import failure_hint

    hint = failure_hint(*_diverged())
    assert hint.startswith("hint: ") and "\n" not in hint and "k_n = 100 past the sampled-data limit" in hint
    assert all(s in hint for s in ("plant.enforce_cc=true", "plant.bending_viscosity=[1.0,1.0,1.0]",
                                   "gains.kn=60", "sensing.dq2_cutoff=200"))
    hint = failure_hint(*_diverged("gains.kn=60", "plant.bending_viscosity=[2.0,2.0,2.0]"))
    assert "plant.enforce_cc=true" in hint and "gains.kn=60" not in hint and "bending_viscosity" not in hint
    assert failure_hint(*_diverged("plant.enforce_cc=true")) is None
    assert failure_hint(*_diverged('plant.actuation="servo"')) is None
    scn, tr = _diverged()
    tr.status = "ok"
    assert failure_hint(scn, tr) is None


def _hint_options(hint: str) -> list[str]:
    return [part.split()[0] for part in hint.split("--set ")[1:]]


def test_torque_on_the_free_chain_prints_one_hint(capsys):
    rc = main(["check", "--actuation", "torque", "--duration", "2", "--set", "transient=0.5", "--no-progress",
               "--bounds", str(ROOT / "bounds" / "paper_mujoco.toml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    hints = [line for line in err if line.startswith("hint: ")]
    assert len(hints) == 1 and len(_hint_options(hints[0])) == 4


def test_every_setting_the_torque_hint_suggests_runs():
    """Each printed suggestion runs the paper scenario in torque actuation for 5 s (status ok)."""
    from harness.cli import failure_hint

    options = _hint_options(failure_hint(*_diverged()))
    assert len(options) == 4
    for opt in options:
        tr = simulate(load_scenario("paper", ['plant.actuation="torque"', "duration=5", "transient=1", opt]))
        assert tr.status == "ok" and len(tr) == 5000, (opt, tr.message)


# ------------------------------------------------------------------- 9: the guide's skeleton runs as written
def test_the_guide_skeleton_runs_as_written(tmp_path, monkeypatch, capsys):
    import re
    import shlex

    text = (ROOT / "docs" / "guide" / "controllers.md").read_text(encoding="utf-8")
    (code,) = re.findall(r"```python\n(.*?)```", text, re.S)
    (tmp_path / "my_controller.py").write_text(code)
    commands = [shlex.split(line)[1:] for block in re.findall(r"```sh\n(.*?)```", text, re.S)
                for line in block.splitlines() if line.startswith("teleop ")]
    assert len(commands) == 2
    monkeypatch.chdir(tmp_path)
    for i, argv in enumerate(commands):
        assert main([*argv, "--out", f"o{i}", "--no-progress"]) == 0, capsys.readouterr().err
        assert json.loads((tmp_path / f"o{i}" / "metrics.json").read_text())["status"] == "ok"
