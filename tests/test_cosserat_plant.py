"""The Cosserat-rod plant in the harness: the stepped loop (harness/loop/stepped_loop.py) checked
against the compiled analytic loop, the paper scenario on the rod (status, determinism, rod tip vs
CC-fit tip), one-line errors for bad [plant.cosserat] settings before anything runs, and the CLI
outputs with the rod centreline in the recording."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers import master as master_model
from controllers.slave import gauss_legendre01
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.loop import simulate
from harness.loop.analytic_loop import simulate_analytic
from harness.loop.fast import K
from harness.loop.stepped_loop import simulate_stepped
from harness.plant import build_plant
from harness.plant.stepped import SteppedPlant

ROOT = Path(__file__).resolve().parents[1]
FIELDS = ("q1", "dq1", "q2", "dq2", "e1", "e2", "beta", "ya", "deN", "T1", "T2", "u2")


class AnalyticStepped:
    """The analytic plant as a SteppedPlant: torque actuation, RK4 steps of plant.physics_dt with the
    same kernel (plant_accel) and the same stage arithmetic as the compiled analytic loop."""

    kind = "analytic-stepped"
    actuation = "torque"

    def __init__(self, scn):
        self.physics_dt = scn.plant.physics_dt
        self.mpk = master_model.packed(scn.plant_master)
        self.spk = scn.plant_slave.packed()
        self.nodes, self.weights = gauss_legendre01(scn.slave.n_quad)
        self.F = np.array([*scn.interaction_forces[0], *scn.interaction_forces[1]], dtype=float)
        self.s, self.T1, self.T2 = np.zeros(16), np.zeros(2), np.zeros(6)
        self.k = [np.empty(16) for _ in range(4)]

    def reset(self, state0):
        self.s[:] = state0

    def command(self, T1, T2, q2_ref, dq2_ref, q2_sensed):
        self.T1[:] = T1
        self.T2[:] = T2

    def advance(self, dt):
        n = round(dt / self.physics_dt)
        h = dt / n
        s, k = self.s, self.k
        args = (self.mpk, self.spk, self.nodes, self.weights)
        for _ in range(n):
            K.plant_accel(*args, s, self.T1, self.T2, self.F, k[0])
            K.plant_accel(*args, s + 0.5 * h * k[0], self.T1, self.T2, self.F, k[1])
            K.plant_accel(*args, s + 0.5 * h * k[1], self.T1, self.T2, self.F, k[2])
            K.plant_accel(*args, s + h * k[2], self.T1, self.T2, self.F, k[3])
            for i in range(16):
                s[i] += h / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i])
        return 0

    def true_state(self, out):
        out[:] = self.s

    def slave_tip(self):
        return np.zeros(2)

    def geometry(self):
        return {}


def test_stepped_loop_equals_the_compiled_analytic_loop():
    """Noise, laws and record of the Python-level loop are the compiled loop's, bit for bit (40 dB)."""
    scn = load_scenario(None, ["plant.kind=analytic", "duration=1.0"])
    plant = AnalyticStepped(scn)
    assert isinstance(plant, SteppedPlant)
    a, b = simulate_analytic(scn), simulate_stepped(scn, plant)
    assert a.status == b.status == "ok" and len(a) == len(b) == 1000
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


@pytest.fixture(scope="module")
def rod_runs():
    scn = load_scenario(ROOT / "scenarios" / "paper.toml",
                        ["plant.kind=cosserat", "duration=0.5", "transient=0.1"])
    return scn, simulate(scn), simulate(scn)


def test_paper_scenario_runs_on_the_rod(rod_runs):
    scn, a, _ = rod_runs
    assert a.status == "ok", a.message
    assert len(a) == 500 and a.meta["plant"] == "cosserat"
    assert a.x2_plant.shape == (500, 2) and a.master_pos.shape == (500, 3, 3)
    # the rod tip (plant's own) vs the analytic tip of the CC fit: the rod is nearly CC here
    gap = np.linalg.norm(a.x2 - a.x2_plant, axis=1)
    assert gap.max() < 2e-3
    # master tip of the recording geometry = forward kinematics of the recorded q1
    x1w = a.master_pos[:, 2, [0, 2]] - np.asarray(a.meta["master_base"])[[0, 2]]
    np.testing.assert_allclose(x1w, a.x1, atol=1e-12)
    geo = a.meta["geometry"]
    n_nodes = 3 * scn.plant.cosserat.elements_per_section + 1
    assert geo["centreline"].shape == (500, n_nodes, 3) and geo["sections"].shape == (500, 4, 3)
    np.testing.assert_allclose(geo["centreline"][:, 0], np.tile(a.meta["slave_base"], (500, 1)), atol=1e-12)


def test_same_seed_same_rod_run(rod_runs):
    _, a, b = rod_runs
    for f in FIELDS + ("x2_plant",):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    np.testing.assert_array_equal(a.meta["geometry"]["centreline"], b.meta["geometry"]["centreline"])


BAD = [
    (["plant.cosserat.dt=1e-3"], "plant.cosserat.dt = 0.001: too large for 10 elements"),
    (["plant.cosserat.dt=3e-5"], "plant.cosserat.dt = 3e-05: must divide control_dt"),
    (["plant.cosserat.elements_per_section=40", "plant.cosserat.dt=1e-4"], "plant.cosserat.dt"),
    (["plant.slave.bending_stiffness=[0,3,1]"], "plant.slave.bending_stiffness"),
    (["slave.extension_stiffness=[1000,0,400]"], "slave.extension_stiffness"),
    (["plant.cosserat.elements_per_section=1"], "plant.cosserat.elements_per_section = 1"),
    (["plant.cosserat.elastic_law=cubic"], "plant.cosserat.elastic_law"),
    (["plant.bending_viscosity=[-1,0,0]"], "plant.bending_viscosity"),
]


@pytest.mark.parametrize("overrides, text", BAD)
def test_bad_cosserat_settings_are_one_line_errors_before_running(overrides, text):
    with pytest.raises(ConfigError) as ei:
        build_plant(load_scenario(None, ["plant.kind=cosserat", *overrides]))
    msg = str(ei.value)
    assert text in msg and "\n" not in msg


@pytest.mark.slow
def test_cli_bad_setting_exit_2_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "harness.cli", "run", "--plant", "cosserat", "--set",
                        "plant.cosserat.dt=0.002", "--out", str(tmp_path / "x")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "plant.cosserat.dt" in lines[0], r.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_cli_writes_outputs_with_the_rod_in_the_recording(tmp_path):
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "harness.cli", "run", "--plant", "cosserat",
                        "--duration", "0.2", "--out", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    for name in ("run.rrd", "metrics.json", "config.toml", "fig3_e2.png", "shapes.png"):
        assert (out / name).is_file(), name
    from rerun.chunk import RrdReader

    rows = {}
    for c in RrdReader(str(out / "run.rrd")).stream().to_chunks():
        if not c.is_static:
            rows[c.entity_path] = rows.get(c.entity_path, 0) + c.num_rows
    # one centreline strip per logged 3-D scene: the geometry goes at the display rate
    # (record.DEFAULT_GEOMETRY_RATE, every k-th of the 200 control steps, plus the last one)
    from harness.output.record import DEFAULT_GEOMETRY_RATE

    every = int(round(1.0 / (DEFAULT_GEOMETRY_RATE * 0.001)))
    logged = len(set(range(0, 200, every)) | {199})
    assert rows.get("/world/slave/rod") == logged
    assert rows.get("/world/slave/sections") == logged
    assert load_scenario(out / "config.toml").plant.kind == "cosserat"


def test_cosserat_settings_and_viscosities_are_sweep_factors():
    from harness.studies.cases import expand_cases
    from harness.studies.executor import run_case
    from harness.studies.study import load_study

    study = load_study({
        "study": {"name": "rod", "metrics": ["e2_rms", "sim_time_reached"],
                  "set": ["plant.kind=cosserat", "duration=0.05"]},
        "factor": [{"name": "eta_b", "param": "plant.bending_viscosity", "scale": [1.0, 2.0]},
                   {"name": "n", "param": "plant.cosserat.elements_per_section", "values": [6, 10]}]})
    cases = expand_cases(study)
    got = sorted((c.scenario.plant.bending_viscosity[0], c.scenario.plant.cosserat.elements_per_section)
                 for c in cases)
    eta = load_scenario(None).plant.bending_viscosity[0]
    assert got == [(eta, 6), (eta, 10), (2 * eta, 6), (2 * eta, 10)]
    case = next(c for c in cases if c.scenario.plant.cosserat.elements_per_section == 6)
    out = run_case({"case_id": case.case_id, "scenario": case.scenario, "metrics": study.metrics})
    assert out["status"] == "ok", out
    assert out["metrics"]["sim_time_reached"] == pytest.approx(0.05)


def test_cosserat_schema_covers_every_field():
    import dataclasses

    from harness.config.scenario import CosseratConfig, Scenario
    from harness.config.schema import paths

    assert {f"plant.cosserat.{f.name}" for f in dataclasses.fields(CosseratConfig)} <= set(paths(Scenario))
    assert {"plant.cosserat.dt", "plant.bending_viscosity"} <= set(paths(Scenario))


def test_paper_controller_fast_path_equals_its_step_interface():
    """The paper's law through the stepped loop's one-call fast path ("paper") and through the public
    interface ("paper_interface", the same registered class) give the same rows, with noise and without."""
    for snr in ("40", "none"):
        base = ["plant.kind=analytic", "duration=0.5", f"snr_db={snr}"]
        a = simulate_stepped(load_scenario(None, base), AnalyticStepped(load_scenario(None, base)))
        scn = load_scenario(None, [*base, "controller.name=paper_interface"])
        b = simulate_stepped(scn, AnalyticStepped(scn))
        assert (a.meta["controller"], b.meta["controller"]) == ("paper", "paper_interface")
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f"{f}, snr {snr}")


@pytest.mark.parametrize("name", ["paper_interface", "paper_no_null"])
def test_python_controller_runs_on_the_rod(name):
    """A controllers.interface.Controller runs on the Cosserat plant through the one Python-level loop
    (0.3 s, paper scenario): status ok, every step recorded, the rod's geometry kept, and the coordination
    error stays bounded (the paper's law on the compiled path reaches the same plant)."""
    scn = load_scenario(ROOT / "scenarios" / "paper.toml",
                        ["plant.kind=cosserat", "duration=0.3", "transient=0.1", f'controller.name="{name}"'])
    tr = simulate(scn)
    assert tr.status == "ok", tr.message
    assert len(tr) == 300 and tr.meta["controller"] == name
    assert tr.meta["geometry"]["centreline"].shape[0] == 300 and tr.x2_plant.shape == (300, 2)
    assert np.all(np.isfinite(tr.q2)) and np.max(np.abs(tr.e2)) < 0.05
