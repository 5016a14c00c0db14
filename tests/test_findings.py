"""Findings (`teleop findings`, harness.studies.findings): the file format's errors, the checks, and in
the slow tier every shipped finding rerun: each must hold, and the findings table in docs/ must be the one
the command writes today."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from harness.config.errors import ConfigError
from harness.studies.findings import available, finding_from_dict, load_finding, run_finding

ROOT = Path(__file__).resolve().parents[1]

BASE = {"finding": {"title": "t", "claim": "c", "set": ["plant.kind='analytic'", "duration=0.3",
                                                        "transient=0.1"]},
        "run": [{"name": "a"}]}


def test_every_shipped_finding_loads():
    names = available()
    assert "eq28_sign_typo" in names and len(names) >= 5
    for n in names:
        f = load_finding(n)
        assert f.runs and (f.limits or any(r.bounds for r in f.runs)), n


@pytest.mark.parametrize(("patch", "field"), [
    ({"claim": {"a": {"e2_rms_maxx": 1.0}}}, "bounds.e2_rms_maxx"),
    ({"claim": {"ratio_x": 1.0}}, "claim.ratio_x"),
    ({"claim": {"b": {"status_ok": True}}}, "claim.b"),
    ({"run": [{"name": "a", "measure": ["nope"]}], "claim": {"a": {"status_ok": True}}}, "run[0].measure"),
    ({"run": [], "claim": {"x_max": 1.0}}, "run"),
    ({"claim": {}}, "claim"),
    ({"run": [{"name": "a", "simulate": False}], "claim": {"x_max": 1.0}}, "run[0].simulate"),
])
def test_bad_finding_files_name_the_field(patch, field):
    raw = {**BASE, **patch}
    with pytest.raises(ConfigError) as e:
        finding_from_dict(raw, "bad")
    assert field in str(e.value), str(e.value)


def test_a_claim_that_does_not_hold_is_reported():
    """The checks can fail: a too-tight bound on a short analytic run does not hold."""
    ok = finding_from_dict({**BASE, "claim": {"a": {"status_ok": True, "e1_rms_max": 1.0}}}, "ok")
    bad = finding_from_dict({**BASE, "claim": {"a": {"status_ok": True, "e1_rms_max": 1e-12},
                                               "a_e2_rms_min": 1e3}}, "bad")
    assert run_finding(ok).holds
    res = run_finding(bad)
    assert not res.holds
    assert {c.quantity for c in res.checks if not c.holds} == {"a.e1_rms", "a.e2_rms"}


def test_a_finding_whose_measure_fails_does_not_hold():
    """An exception while running is the finding's error, reported, not a traceback."""
    raw = {"finding": {"title": "t", "claim": "c", "set": ["plant.kind='analytic'", "snr_db='none'",
                                                          "duration=0.02", "transient=0.005"]},
           "run": [{"name": "a", "measure": ["eq28"]}], "claim": {"a_eq28_corrected_max": 1.0}}
    res = run_finding(finding_from_dict(raw, "short"))  # 20 steps: eq28 needs 32
    assert not res.holds and "IndexError" in res.error


def test_a_bad_override_is_an_input_error_naming_the_finding():
    raw = {**BASE, "run": [{"name": "a", "set": ["plant.segments=0"]}], "claim": {"a": {"status_ok": True}}}
    with pytest.raises(ConfigError) as e:
        run_finding(finding_from_dict(raw, "bad"))
    assert "finding bad, run a" in str(e.value) and "plant.segments" in str(e.value)


@pytest.mark.slow
def test_every_finding_holds_and_the_docs_table_is_current(tmp_path):
    table = tmp_path / "findings-table.md"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-m", "harness.cli", "findings", "--table", str(table),
                          "--figures", str(tmp_path / "figures")], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f"{len(available())} of {len(available())} findings hold" in res.stdout
    assert table.read_text() == (ROOT / "docs" / "findings-table.md").read_text(), \
        "docs/findings-table.md is not the table `teleop findings` writes today: rerun it"
    assert sorted(p.name for p in (tmp_path / "figures").glob("*.png")) == \
        sorted(p.name for p in (ROOT / "docs" / "figures").glob("*.png"))
