"""The controller interface (controllers/interface.py, harness/config/controller.py, interface_loop.py):
the paper's law through the interface equals the compiled loop bit for bit; an independent numpy
re-implementation of the paper's law (written here from the equations) matches it to 1e-9; every
failure mode is one line; controller sweeps; CLI selection."""

from __future__ import annotations

import ast
import csv
import json
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest
from reference_models import null_space_reference

from controllers import master as mm
from controllers import slave as sm
from controllers.interface import Action, Controller, ControllerDiverged, Observation
from harness.api import load_scenario
from harness.cli import main
from harness.config.errors import ConfigError
from harness.loop import simulate
from harness.loop.interface_adapter import make_controller
from harness.loop.trajectory import ROW_FIELDS

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = "examples/controllers/jacobian_transpose.py:JacobianTransposePD"
SHORT = ["duration=0.3"]


def _scn(*over):
    return load_scenario(None, [*SHORT, *over])


def _same(a, b):
    assert len(a) == len(b) and a.status == b.status, (a.status, a.message, b.status, b.message)
    for f in ROW_FIELDS:
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    for f in ("x2_plant", "body_pos", "body_quat", "master_pos"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f


# --------------------------------------------------------------------------------- bit for bit
@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
@pytest.mark.parametrize("snr", ["40", "none"])
def test_paper_through_interface_is_bit_for_bit(actuation, snr):
    over = [f'plant.actuation="{actuation}"', f"snr_db={snr}"]
    compiled = simulate(_scn(*over))
    py = simulate(_scn(*over, 'controller.name="paper_interface"'))
    assert compiled.status == "ok" and len(compiled) == 300
    _same(compiled, py)
    if actuation == "muscle":  # the muscle groups' commands, as both loops count them
        assert compiled.meta["muscle_saturated_steps"] == py.meta["muscle_saturated_steps"]


def test_analytic_plant_applies_the_actuation_delay_like_the_interface_path():
    """The compiled analytic loop delays the commands through the same ring as the Python-stepped loop
    (bit for bit), and the delay changes the run."""
    over = ["plant.kind=analytic", "snr_db=none", "plant.actuation_delay=0.003"]
    delayed = simulate(_scn(*over))
    _same(delayed, simulate(_scn(*over, 'controller.name="paper_interface"')))
    undelayed = simulate(_scn(*over[:2]))
    assert delayed.status == undelayed.status == "ok"
    assert not np.array_equal(delayed.q2, undelayed.q2)


def test_paper_through_interface_bit_for_bit_with_delay_and_feedforward_off():
    over = ["plant.actuation_delay=0.002", "plant.servo_feedforward=false"]
    _same(simulate(_scn(*over)), simulate(_scn(*over, 'controller.name="paper_interface"')))


# --------------------------------------------------------------------- independent re-implementation
class NumpyPaper(Controller):
    """The paper's law, written from the equations with plain numpy and the controllers/ models:
    (12)-(13) master; (17)-(18) slave with (23) de_N, (26) J_phi, (27) phi_N, (29)-(33) sub-task."""

    name = "numpy_paper"

    def step(self, obs: Observation) -> Action:
        c, a = self.ctx, self.action
        g = c.gains
        q1, dq1, q2, dq2 = obs.q1.copy(), obs.dq1.copy(), obs.q2.copy(), obs.dq2.copy()
        J1 = mm.jacobian(c.master, q1)
        x1, dx1 = mm.fk(c.master, q1), J1 @ dq1
        e1, de1 = obs.x_d - x1, obs.dx_d - dx1  # (11)
        a1 = obs.ddx_d + g.k1 * de1 + g.k2 * e1
        u1 = np.linalg.solve(J1, a1 - mm.jacobian_dot(c.master, q1, dq1) @ dq1)  # (13)
        a.T1[:] = mm.mass_matrix(c.master, q1) @ u1 + mm.nle(c.master, q1, dq1) - J1.T @ obs.F1  # (12)
        J2, Jd2 = sm.jacobian(c.slave, q2), sm.jacobian_dot(c.slave, q2, dq2)
        x2 = sm.tip_position(c.slave, q2)
        e2, de2 = x1 - x2, dx1 - J2 @ dq2  # (16)
        A = J2 @ J2.T
        Ai = np.linalg.inv(A)
        Jp = J2.T @ Ai  # (7)
        dA = Jd2 @ J2.T + J2 @ Jd2.T
        Jpd = Jd2.T @ Ai - J2.T @ Ai @ dA @ Ai
        P = np.eye(6) - Jp @ J2
        _, _, gv, gd = null_space_reference(c.subtask, c.slave, g.ky, g.ks, q2, dq2)  # (29)-(33)
        deN = P @ (gv - dq2)  # (23)
        Jphi = Jpd @ J2 + Jp @ Jd2 @ Jp @ J2  # (26)
        phi = P @ (gd + g.kn * deN) - Jphi @ (gv - dq2)  # (27)
        u2 = Jp @ (a1 + g.k3 * de2 + g.k4 * e2 - Jd2 @ dq2) + phi  # (18)
        M2, N2 = sm.mass_and_nle(c.slave, q2, dq2)
        a.T2[:] = M2 @ u2 + N2 - J2.T @ obs.F2  # (17)
        a.u2[:] = u2
        a.deN[:] = deN
        return a


def test_numpy_reimplementation_matches_paper_controller_to_1e9():
    scn = _scn('plant.actuation="torque"', "snr_db=30")
    ref = simulate(scn)  # states visited by the compiled closed loop (torque plant, noisy)
    paper, ctx = make_controller(load_scenario(None, [*SHORT, 'controller.name="paper_interface"']))
    paper.reset(ctx)
    mine = NumpyPaper()
    mine.reset(ctx)
    obs = Observation()
    rng = np.random.default_rng(1)
    for k in range(0, len(ref), 7):
        obs.sensed[:] = np.concatenate([ref.q1[k], ref.dq1[k], ref.q2[k], ref.dq2[k]])
        obs.sensed += 1e-3 * rng.standard_normal(16) * np.abs(obs.sensed)  # off-trajectory too
        obs.x_d[:] = ref.xd[k]
        obs.dx_d[:] = rng.standard_normal(2) * 0.01
        obs.ddx_d[:] = rng.standard_normal(2) * 0.01
        obs.F[:] = rng.standard_normal(4)
        a, b = paper.step(obs), mine.step(obs)
        for f in ("T1", "T2", "u2", "deN"):
            x, y = getattr(a, f), getattr(b, f)
            assert np.max(np.abs(x - y)) <= 1e-9 * (1.0 + np.max(np.abs(x))), (f, k, x, y)


def test_numpy_reimplementation_closed_loop_matches_compiled(tmp_path):
    mod = tmp_path / "mine.py"
    mod.write_text(f"from {__name__} import NumpyPaper\n")
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    try:
        ref = simulate(_scn("snr_db=none", "duration=0.2"))
        got = simulate(_scn("snr_db=none", "duration=0.2", f'controller.name="{mod}:NumpyPaper"'))
    finally:
        sys.path.remove(str(ROOT / "tests"))
    assert got.status == "ok" and len(got) == len(ref) == 200
    for f in ("q1", "q2", "dq2", "T1", "T2", "u2"):
        x, y = getattr(ref, f), getattr(got, f)
        assert np.max(np.abs(x - y)) <= 1e-9 * (1.0 + np.max(np.abs(x))), f


# --------------------------------------------------------------------------------- failure modes
BAD = textwrap.dedent('''
    import numpy as np
    from controllers.interface import Controller
    from controllers.baselines import PaperNoNullSpace

    class Fails(PaperNoNullSpace):
        at = 12
        what = "raise"

        def step(self, obs):
            a = super().step(obs)
            if obs.k == self.at:
                if self.what == "raise":
                    raise RuntimeError("boom")
                if self.what == "shape":
                    a.T2 = np.zeros(5)
                if self.what == "nan":
                    a.T1[0] = np.nan
                if self.what == "inf":
                    a.u2[3] = np.inf
                if self.what == "none":
                    return None
            return a

    class Raises(Fails):
        what = "raise"

    class Shape(Fails):
        what = "shape"

    class NaN(Fails):
        what = "nan"

    class Inf(Fails):
        what = "inf"

    class ReturnsNone(Fails):
        what = "none"

    class NoStep:
        def reset(self, ctx):
            pass

    not_a_class = 3
''')


@pytest.fixture()
def bad_file(tmp_path):
    p = tmp_path / "bad_controllers.py"
    p.write_text(BAD)
    return p


@pytest.mark.parametrize("cls, text", [
    ("Raises", "raised RuntimeError: boom at step 12 (t = 0.012 s)"),
    ("Shape", "returned T2 of shape (5,) (expected (6,)) at step 12 (t = 0.012 s)"),
    ("NaN", "returned NaN in T1"),
    ("Inf", "returned inf in u2"),
    ("ReturnsNone", "returned None instead of an Action at step 12"),
])
def test_failing_controller_stops_the_run_keeping_partial_outputs(bad_file, cls, text):
    name = f"{bad_file}:{cls}"
    tr = simulate(_scn(f'controller.name="{name}"'))
    assert tr.status == "error"
    assert text in tr.message and repr(name) in tr.message and "\n" not in tr.message
    assert len(tr) == 12 and tr.meta["failed_controller"] == name  # steps 0..11 kept


def test_failing_controller_cli_exit_1_with_outputs(bad_file, tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", "--controller", f"{bad_file}:Shape", "--duration", "0.05", "--out", str(out),
               "--no-progress"])
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "returned T2 of shape (5,)" in err[0]
    assert (out / "config.toml").is_file() and (out / "metrics.json").is_file()
    assert json.loads((out / "metrics.json").read_text())["status"] == "error"


@pytest.mark.parametrize("name, text", [
    ("{f}:NoStep", "lacks the controller interface: no method step"),
    ("{f}:Missing", "has no attribute 'Missing'"),
    ("{f}:not_a_class", "is not a class"),
    ("{d}/nope.py:X", "not found"),
    ("{d}/syntax.py:X", "cannot import"),
    ("no_such_module_xyz:X", "cannot import no_such_module_xyz: ModuleNotFoundError"),
    ("paperr", "unknown built-in controller"),
])
def test_unloadable_controller_is_one_line_exit_2_nothing_written(bad_file, tmp_path, capsys, name, text):
    (tmp_path / "syntax.py").write_text("def (:\n")
    name = name.format(f=bad_file, d=tmp_path)
    with pytest.raises(ConfigError, match="controller.name") as ei:
        load_scenario(None, [f'controller.name="{name}"'])
    assert text in str(ei.value)
    out = tmp_path / "never"
    rc = main(["run", "--controller", name, "--duration", "0.05", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and text in err[0] and not out.exists()


@pytest.mark.parametrize("over, text", [
    (['controller.name="dls_ik"', 'plant.actuation="torque"'], "supports actuation 'servo' only"),
    (['controller.name="dls_ik"', 'plant.kind="analytic"'], "analytic plant"),
    ([f'controller.name="{EXAMPLE}"'], "supports actuation 'torque' only"),
    (['controller.name="dls_ik"', "controller.params.gian=3"], "controller.params.gian = 3: unknown key"),
    (['controller.name="dls_ik"', "controller.params.gain=-1"], "controller.params.gain = -1.0: must be > 0"),
    (['controller.name="dls_ik"', 'controller.params.gain="x"'], "controller.params.gain = 'x': must be a"),
    (['controller.name="paper_no_null"', "controller.params.k=1"], "controller.params.k = 1: unknown key"),
    (["controller.params.k=nan"], "controller.params.k = nan: must be finite"),
])
def test_bad_controller_selection_is_one_config_error(over, text):
    with pytest.raises(ConfigError) as ei:
        load_scenario(None, over)
    assert text in str(ei.value) and "\n" not in str(ei.value)


def test_controller_diverged_is_status_diverged(tmp_path):
    p = tmp_path / "div.py"
    p.write_text("from controllers.baselines import PaperNoNullSpace\n"
                 "from controllers.interface import ControllerDiverged\n"
                 "class Div(PaperNoNullSpace):\n"
                 "    def step(self, obs):\n"
                 "        if obs.k == 5:\n"
                 "            raise ControllerDiverged('gave up')\n"
                 "        return super().step(obs)\n")
    tr = simulate(_scn(f'controller.name="{p}:Div"'))
    # as in the compiled loop, the row of the step that diverged is recorded (steps 0..5)
    assert tr.status == "diverged" and "gave up at step 5" in tr.message and len(tr) == 6
    assert issubclass(ControllerDiverged, RuntimeError)


# --------------------------------------------------------------------------------- selection, CLI
@pytest.mark.slow
def test_cli_selection_by_name_and_path_writes_resolved_params(tmp_path, capsys):
    out = tmp_path / "dls"
    assert main(["run", "--controller", "dls_ik", "--set", "controller.params.gain=15", "--duration", "0.1",
                 "--out", str(out), "--no-progress"]) == 0
    cfg = tomllib.loads((out / "config.toml").read_text())
    assert cfg["controller"] == {"name": "dls_ik", "params": {"gain": 15.0, "damping": 0.01},
                                 "step_timeout": 10.0}
    assert load_scenario(out / "config.toml").controller.params == {"gain": 15.0, "damping": 0.01}
    out2 = tmp_path / "jt"
    assert main(["run", "--controller", EXAMPLE, "--actuation", "torque", "--set", "plant.enforce_cc=true",
                 "--duration", "0.1", "--out", str(out2), "--no-progress"]) == 0
    cfg = tomllib.loads((out2 / "config.toml").read_text())
    path, _, cls = EXAMPLE.rpartition(":")  # config.toml replays from anywhere: the absolute path
    assert cfg["controller"]["name"] == f"{Path(path).resolve()}:{cls}"
    assert set(cfg["controller"]["params"]) == {"kp", "kd", "joint_damping", "posture"}
    assert "status ok" in capsys.readouterr().out


def test_teleop_controllers_lists_builtins(capsys):
    from controllers.baselines import BUILTINS

    assert main(["controllers"]) == 0
    out = capsys.readouterr().out.splitlines()
    for name in BUILTINS:
        assert any(line.split()[0] == name for line in out), name
    assert "paper_no_null" in BUILTINS and "dls_ik" in BUILTINS


@pytest.mark.slow
def test_baselines_track_on_mujoco_servo():
    """Both built-in baselines follow the master on the paper scenario (1 s, servo plant): the
    coordination error stays at the millimetre level of the paper's law."""
    for name in ("paper_no_null", "dls_ik"):
        tr = simulate(_scn(f'controller.name="{name}"', "duration=1.0"))
        assert tr.status == "ok", (name, tr.message)
        assert np.max(np.abs(tr.e2[200:])) < 0.01, name


# --------------------------------------------------------------------------------- sweeps
@pytest.mark.slow
def test_controller_comparison_sweep_writes_one_row_per_case(tmp_path):
    from harness.studies.sweep import run_sweep

    doc = {"study": {"name": "ctl", "set": ["duration=0.1", "transient=0.0"],
                     "metrics": ["e1_rms", "e2_rms", "beta_min"]},
           "factor": [{"name": "controller", "param": "controller", "values": ["paper", "paper_no_null",
                                                                             "dls_ik"]},
                      {"name": "slave_mass", "param": "plant.slave.masses", "scale": [0.8, 1.2]}]}
    res = run_sweep(doc, out=tmp_path, workers=1, progress=False)
    rows = [json.loads(line) for line in (tmp_path / "results.jsonl").read_text().splitlines() if line]
    assert len(rows) == 6 and {r["status"] for r in rows} == {"ok"}
    assert sorted((r["params"]["controller"], r["params"]["slave_mass"]) for r in rows) == sorted(
        (c, s) for c in ("paper", "paper_no_null", "dls_ik") for s in (0.8, 1.2))
    with open(tmp_path / "summary.csv", encoding="utf-8") as fh:
        assert len(list(csv.DictReader(fh))) == 6
    assert (tmp_path / "metric_vs_slave_mass.png").is_file()
    assert res is not None


# --------------------------------------------------------------------------------- examples as documented
def _documented_commands(path: Path) -> list[list[str]]:
    """The `teleop ...` commands of an example's docstring (backslash continuations joined)."""
    import shlex

    text = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    text = text.replace("\\\n", " ")
    return [shlex.split(line.strip())[1:] for line in text.splitlines() if line.strip().startswith("teleop ")]


@pytest.mark.parametrize("example", sorted((ROOT / "examples" / "controllers").glob("*.py")),
                         ids=lambda p: p.name)
@pytest.mark.slow
def test_every_example_command_works_as_written(example, tmp_path, monkeypatch, capsys):
    """Each command an example's docstring gives succeeds as written (cut to 0.3 s; outputs in tmp),
    from the checkout's root, where its paths are relative to."""
    monkeypatch.chdir(ROOT)
    commands = _documented_commands(example)
    assert commands, f"{example.name} documents no teleop command"
    for i, argv in enumerate(commands):
        if "--duration" in argv:
            argv[argv.index("--duration") + 1] = "0.3"
        extra = ["--out", str(tmp_path / f"c{i}")] if argv[0] == "run" else []
        assert main([*argv, *extra, "--no-progress"]) == 0, (example.name, argv, capsys.readouterr())


def test_a_controller_declaring_its_plants_is_refused_elsewhere_in_one_line(tmp_path):
    """A controller that declares `plants` is refused on another plant kind before anything runs, with one
    line naming the field and what it needs."""
    src = tmp_path / "only_analytic.py"
    src.write_text(textwrap.dedent("""
        from controllers.baselines import PaperNoNullSpace

        class OnlyAnalytic(PaperNoNullSpace):
            plants = ("analytic",)
    """))
    name = f"{src}:OnlyAnalytic"
    assert load_scenario(None, [f'controller.name="{name}"', "plant.kind=analytic"]).controller.name == name
    with pytest.raises(ConfigError) as e:
        load_scenario(None, [f'controller.name="{name}"'])
    assert "runs on plant.kind 'analytic' only, not 'mujoco'" in str(e.value)
    assert "\n" not in str(e.value)
