"""The shipped bounds hold for the paper scenario on the MuJoCo plant (default N, both actuation
modes) and catch deliberately broken controllers (sign error, dropped null-space term).  Servo runs
the default plant (the free chain with material damping); torque mode runs the chain with the CC
equalities, as bounds/paper_mujoco_torque.toml says: on the free chain at the default material
damping the paper's gains diverge in torque mode (docs/stability map).  Muscle actuation runs the free
chain with gains.kn = 10 (bounds/paper_mujoco_muscle.toml), and its bounds see a slave-mass mismatch
that the servo plant hides."""

from pathlib import Path

import pytest

from harness.config.bounds import check_bounds, load_bounds
from harness.config.load import load_scenario
from harness.loop import simulate
from harness.loop.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
BOUNDS = {"servo": ROOT / "bounds" / "paper_mujoco.toml",
          "torque": ROOT / "bounds" / "paper_mujoco_torque.toml",
          "muscle": ROOT / "bounds" / "paper_mujoco_muscle.toml"}


PLANT = {"servo": (), "torque": ("plant.enforce_cc=true",), "muscle": ("gains.kn=10",)}


def run(actuation: str, *overrides: str) -> dict:
    scn = load_scenario(ROOT / "scenarios" / "paper.toml",
                        [f"plant.actuation='{actuation}'", *PLANT[actuation], *overrides])
    assert scn.plant.kind == "mujoco" and scn.plant.segments == 8
    return compute_metrics(simulate(scn), scn)


@pytest.mark.slow
@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
def test_paper_scenario_meets_shipped_bounds(actuation):
    metrics = run(actuation)
    violations = check_bounds(metrics, load_bounds(BOUNDS[actuation]))
    assert not violations, "\n".join(map(str, violations))
    assert metrics["mujoco_warnings"] == 0


@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
def test_bounds_catch_a_sign_error(actuation):
    metrics = run(actuation, "faults.e2_sign=-1", "duration=3.0", "transient=0.5")
    bounds = {v.bound for v in check_bounds(metrics, load_bounds(BOUNDS[actuation]))}
    assert metrics["status"] == "diverged"
    assert "status_ok" in bounds


@pytest.mark.slow
def test_bounds_catch_a_dropped_null_space_term():
    """Servo mode stays stable without phi_N and e2 is unaffected (phi_N lives in the null space), so
    only the null-space and range bounds can see it."""
    metrics = run("servo", "faults.null_space_scale=0")
    violations = {v.bound for v in check_bounds(metrics, load_bounds(BOUNDS["servo"]))}
    assert {"deN_rms_max", "range_violation_max"} <= violations
    assert "e2_rms_max" not in violations


@pytest.mark.slow
def test_torque_bounds_catch_a_dropped_null_space_term():
    """In torque mode (CC chain with the default material damping) the arm without phi_N runs through
    the 20 s, but its null-space velocity error grows 4x (measured deN_rms 0.30 against 0.061-0.072
    intact): the deN bound catches it.  (Without material damping it drifted until it diverged.)"""
    metrics = run("torque", "faults.null_space_scale=0")
    violations = {v.bound for v in check_bounds(metrics, load_bounds(BOUNDS["torque"]))}
    assert "deN_rms_max" in violations


@pytest.mark.slow
def test_muscle_bounds_see_the_slave_mass():
    """With muscles the slave's inertia enters: 1.5x the slave mass fails the muscle bounds (measured
    e2_rms 115 mm against 48.6-51.6 mm nominal), where the servo plant passes even at 3x."""
    metrics = run("muscle", "plant.slave.masses=[1.5,1.05,0.6]")
    violations = {v.bound for v in check_bounds(metrics, load_bounds(BOUNDS["muscle"]))}
    assert "e2_rms_max" in violations
    servo = run("servo", "plant.slave.masses=[3.0,2.1,1.2]")
    assert not check_bounds(servo, load_bounds(BOUNDS["servo"]))
