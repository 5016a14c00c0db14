"""The shipped Cosserat bounds (bounds/paper_cosserat.toml) hold for the paper scenario on the rod
(servo, seed 0; slow: 20 s of simulated time) and catch a sign error in (18)."""

from pathlib import Path

import pytest

from harness.config.bounds import check_bounds, load_bounds
from harness.config.load import load_scenario
from harness.loop import simulate
from harness.loop.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
BOUNDS = ROOT / "bounds" / "paper_cosserat.toml"


def run(*overrides: str) -> dict:
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", ["plant.kind=cosserat", *overrides])
    assert scn.plant.actuation == "servo" and scn.plant.cosserat.elements_per_section == 10
    return compute_metrics(simulate(scn), scn)


@pytest.mark.slow
def test_paper_scenario_on_the_rod_meets_shipped_bounds():
    metrics = run()
    violations = check_bounds(metrics, load_bounds(BOUNDS))
    assert not violations, "\n".join(map(str, violations))


def test_rod_bounds_catch_a_sign_error():
    metrics = run("faults.e2_sign=-1", "duration=2.0", "transient=0.5")
    bounds = {v.bound for v in check_bounds(metrics, load_bounds(BOUNDS))}
    assert metrics["status"] == "diverged"
    assert "status_ok" in bounds
