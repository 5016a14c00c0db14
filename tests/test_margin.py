"""Robustness margins (harness.studies.margin, `teleop margin`): the bisection finds the edge a dense sweep
finds, to within its tolerance; non-monotone edges are reported; runs are journaled and resumed."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from harness.config.bounds import check_bounds, load_bounds
from harness.config.load import load_scenario
from harness.studies.margin import PARAMS, Search, margins

CHEAP = ["plant.kind=analytic", "duration=2", "transient=1", "snr_db=none"]
STATUS = {"bounds": {"status_ok": True}}


def _drive(search: Search, passes) -> Search:
    """Run a search against a pass/fail function of the level."""
    while not search.done:
        levels = search.next_levels()
        for lv in levels:
            search.feed(lv, passes(lv))
        search.end_round()
    return search


@pytest.mark.parametrize("edge", [1.37, 3.9, 19.0])
def test_search_brackets_and_bisects_a_monotone_edge(edge):
    s = _drive(Search(PARAMS["slave_mass"], 1.0, 20.0, 0.01, 0.0, 2), lambda x: x <= edge)
    assert s.last_pass <= edge < s.first_fail
    assert s.first_fail / s.last_pass <= 1.01
    assert not s.failed_probes and len(s.probe_levels) == 2
    down = _drive(Search(PARAMS["slave_mass"], 1.0, 0.05, 0.01, 0.0, 2), lambda x: x >= 1 / edge)
    assert down.first_fail < 1 / edge <= down.last_pass
    assert down.last_pass / down.first_fail <= 1.01


def test_search_reports_range_end_and_integer_edges():
    s = _drive(Search(PARAMS["slave_mass"], 1.0, 20.0, 0.01, 0.0, 2), lambda x: True)
    assert s.last_pass == 20.0 and s.first_fail is None
    seg = _drive(Search(PARAMS["segments"], 8.0, 64.0, 0.01, 0.0, 2), lambda x: x <= 23)
    assert (seg.last_pass, seg.first_fail) == (23.0, 24.0)
    low = _drive(Search(PARAMS["segments"], 8.0, 1.0, 0.01, 0.0, 2), lambda x: x >= 3)
    assert (low.last_pass, low.first_fail) == (3.0, 2.0)


def test_search_detects_a_non_monotone_edge():
    """A failing island between the nominal point and the edge the bisection finds is caught by a probe."""
    s = _drive(Search(PARAMS["slave_mass"], 1.0, 20.0, 0.01, 0.0, 3), lambda x: x <= 10 and not 2.5 < x < 4)
    assert s.first_fail is not None and s.last_pass <= 10 < s.first_fail
    assert s.failed_probes and all(2.5 < x < 4 for x in s.failed_probes)


def _dense_pass(levels) -> list[bool]:
    """The dense sweep: each slave-mass scale run by the sweep's worker (`run_case`) and checked."""
    from harness.studies.cases import scenario_id
    from harness.studies.executor import run_case

    bounds = load_bounds(STATUS)
    base = load_scenario(None, CHEAP)
    out = []
    for s in levels:
        m = [round(float(x) * float(s), 12) for x in base.slave.masses]
        scn = load_scenario(None, [*CHEAP, f"plant.slave.masses={m}"])
        res = run_case({"case_id": scenario_id(scn), "scenario": scn, "metrics": ["status"], "record": False})
        out.append(not check_bounds({**res["metrics"], "status": res["status"]}, bounds))
    return out


def test_margin_agrees_with_a_dense_sweep_across_the_edge(tmp_path):
    """Analytic plant, paper law, 2 s: the upper slave-mass margin (rtol 2 %) against a sweep with 0.5 %
    steps across [0.95 margin, 1.05 fail]: the sweep's first failing scale lies in (margin, fail + step]
    and every scale at or below the margin passes."""
    scn = load_scenario(None, CHEAP)
    rows = margins(scn, load_bounds(STATUS), ["slave_mass"], base_set=CHEAP, rtol=0.02, probes=2,
                   out=tmp_path, workers=1, executor="threads")
    up = rows[0].sides["upper"]
    lo_, hi_ = up["margin"], up["fail"]
    assert hi_ is not None and hi_ / lo_ <= 1.02 + 1e-9
    assert up["first_bound"] == "status_ok" and up["metric_at_fail"] == "diverged"
    grid = np.exp(np.arange(math.log(0.95 * lo_), math.log(1.05 * hi_), math.log(1.005)))
    ok = _dense_pass(grid)
    first_fail = next(g for g, p in zip(grid, ok, strict=True) if not p)
    assert lo_ < first_fail <= hi_ * 1.005 + 1e-12
    assert all(p for g, p in zip(grid, ok, strict=True) if g <= lo_)


def test_margins_resume_from_the_journal(tmp_path):
    from harness.studies.executor import run_case

    calls = []

    def counting(case):
        calls.append(case["case_id"])
        return run_case(case)

    scn = load_scenario(None, CHEAP)
    kw = dict(base_set=CHEAP, rtol=0.1, probes=1, out=tmp_path, workers=1, executor="threads",
              case_fn=counting)
    first = margins(scn, load_bounds(STATUS), ["master_mass"], **kw)
    n1 = len(calls)
    assert n1 > 3
    again = margins(scn, load_bounds(STATUS), ["master_mass"], **kw)
    assert len(calls) == n1  # every run read from results.jsonl
    assert again[0].sides == first[0].sides
    rows = (tmp_path / "results.jsonl").read_text().splitlines()
    assert len(rows) == n1 and all(json.loads(r)["case_id"] for r in rows)


def test_parameters_that_do_not_apply_are_listed_not_searched(tmp_path):
    scn = load_scenario(None, CHEAP)
    rows = margins(scn, load_bounds(STATUS), ["segments", "delay", "material_damping"], base_set=CHEAP,
                   out=tmp_path, workers=1, executor="threads")
    assert all(r.note and not r.sides for r in rows)


def test_nominal_failing_is_an_error():
    from harness.config.errors import ConfigError

    scn = load_scenario(None, CHEAP)
    tight = load_bounds({"bounds": {"e2_rms_max": 1e-12}})
    with pytest.raises(ConfigError, match="nominal scenario fails"):
        margins(scn, tight, ["slave_mass"], base_set=CHEAP, workers=1, executor="threads")


def test_cli_margin_writes_table_and_figure(tmp_path, capsys):
    from harness.cli import main

    b = tmp_path / "b.toml"
    b.write_text("[bounds]\nstatus_ok = true\n")
    out = tmp_path / "m"
    rc = main(["margin", "--plant", "analytic", "--set", "duration=2", "--set", "transient=1",
               "--snr", "none", "--bounds", str(b), "--param", "master_mass", "--rtol", "0.2",
               "--probes", "0", "--executor", "threads", "--workers", "1", "--out", str(out),
               "--no-progress"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "| master_mass |" in text
    for name in ("margins.md", "margins.json", "margins.png", "results.jsonl"):
        assert (out / name).stat().st_size > 0


def test_cli_margin_bad_param_is_one_line(tmp_path, capsys):
    from harness.cli import main

    b = tmp_path / "b.toml"
    b.write_text("[bounds]\nstatus_ok = true\n")
    rc = main(["margin", "--plant", "analytic", "--bounds", str(b), "--param", "nonsense", "--out",
               str(tmp_path / "m")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--param" in err[0]


def test_edge_trace_of_two_masses(tmp_path):
    """The 2-D edge: along each ray the margin passes and the failing point fails, and the axis rays agree
    with the 1-D margins of each parameter (same bisection, same tolerance)."""
    from harness.api import margins as api_margins

    rows, edge = api_margins(None, CHEAP, bounds=STATUS, params=["slave_mass"], rtol=0.05, probes=0,
                             out=tmp_path, workers=1, executor="threads", pair=("slave_mass", "master_mass"),
                             n_rays=4)
    assert [round(r["angle_deg"]) for r in edge] == [0, 90, 180, 270]
    # levels are kept to 6 significant digits: the two searches agree to that rounding
    assert edge[0]["p1"] == pytest.approx(rows[0].sides["upper"]["margin"], rel=1e-5)
    assert edge[2]["p1"] == pytest.approx(rows[0].sides["lower"]["margin"], rel=1e-5)
    for r in edge:
        if r["fail_p1"] is not None:
            assert r["first_bound"] == "status_ok"
    assert (tmp_path / "edge.png").stat().st_size > 0 and (tmp_path / "edge.json").exists()
