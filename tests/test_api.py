"""The public Python API (`from harness import ...`), as the README shows it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_readme_example_runs_a_mismatched_plant(tmp_path):
    from harness import Trajectory, load_scenario, run

    scn = load_scenario(None, ["duration=1", "plant.slave.masses=[1.2,0.84,0.48]"])
    assert scn.plant_slave.masses == (1.2, 0.84, 0.48) and scn.slave.masses == (1.0, 0.7, 0.4)
    traj = run(scn)
    assert isinstance(traj, Trajectory) and traj.status == "ok" and len(traj) == scn.n_steps
    e2 = np.abs(traj.e2).max(axis=1)
    assert np.all(np.isfinite(e2))
    assert traj.meta["metrics"]["e2_rms"] > 0
    # the mismatch is measurable: the nominal plant tracks better over the same second
    nominal = run(load_scenario(None, ["duration=1"]))
    assert traj.meta["metrics"]["e2_rms"] != nominal.meta["metrics"]["e2_rms"]


@pytest.mark.slow
def test_run_with_out_writes_what_teleop_run_writes(tmp_path):
    from harness import run

    traj = run(None, ["duration=0.2", "plant.kind='analytic'"], out=tmp_path / "o")
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert {"config.toml", "metrics.json", "run.rrd", "fig3_e2.png"} <= names
    doc = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert doc["status"] == traj.status == "ok"
    assert doc["e2_rms"] == pytest.approx(traj.meta["metrics"]["e2_rms"], rel=1e-15)


def test_load_scenario_checks_the_plant(tmp_path):
    """Plant errors (a scene MJCF that does not compile) are input errors before anything runs."""
    from harness import load_scenario
    from harness.config.errors import ConfigError
    from harness.config.load import load_scenario as load_config_only

    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body name='x'/></worldbody></mujoco>")
    assert load_config_only({"plant": {"scene_xml": str(bad)}}).plant.scene_xml == str(bad)
    with pytest.raises(ConfigError, match=r"plant\.scene_xml.*unusable MJCF"):
        load_scenario({"plant": {"scene_xml": str(bad)}})


def test_import_harness_is_cheap():
    """`import harness` imports no simulation, plotting or recording package."""
    code = ("import sys, harness; heavy = [m for m in ('mujoco', 'matplotlib', 'rerun', 'numba') "
            "if m in sys.modules]; print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


@pytest.mark.parametrize("field, value", [("slave", {"masses": (-1.0, 0.7, 0.4)}),
                                          ("gains", {"kn": 0.0}),
                                          ("plant", {"kind": "analytic", "segments": 0})])
def test_a_scenario_built_in_python_gets_the_checks_of_a_file(field, value):
    """A Scenario edited with dataclasses.replace is refused in one line, as the same values in a file."""
    import dataclasses

    from harness import load_scenario, run
    from harness.config.errors import ConfigError

    scn = load_scenario(None, ["duration=0.1"])
    bad = dataclasses.replace(scn, **{field: dataclasses.replace(getattr(scn, field), **value)})
    with pytest.raises(ConfigError) as e:
        run(bad)
    key = next(iter(value.keys() - {"kind"}))
    assert f"{field}.{key} = " in str(e.value) and "\n" not in str(e.value)
