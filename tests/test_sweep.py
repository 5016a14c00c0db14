"""Mismatch-study sweeps (harness.studies.sweep): expansion, ids, resume, failures, Dask, summary.

Most tests run a cheap stub case function (`stub_case`, top level so worker processes can import
it) through the real process pool; `test_end_to_end_analytic_plant` runs the real simulation.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from controllers.params import MasterParams, SlaveParams
from harness.config.errors import ConfigError
from harness.studies import sweep as sweep_module
from harness.studies.sweep import (
    METRIC_NAMES,
    RESULTS,
    SweepError,
    SweepInterrupted,
    expand_cases,
    load_study,
    read_results,
    run_case,
    run_sweep,
)

ROOT = Path(__file__).resolve().parents[1]
CALLS_ENV = "SWEEP_TEST_CALLS"  # file the stub appends one line per call to (across processes)
PIDS_ENV = "SWEEP_TEST_PIDS"
METRICS = ["e2_rms", "e2_max", "beta_min"]
NOMINAL = SlaveParams()


# --- stub case functions (run in worker processes) ---------------------------------------------------
def _log_call(case: dict) -> None:
    calls = os.environ.get(CALLS_ENV)
    if calls:
        with open(calls, "a") as fh:
            fh.write(case["case_id"] + "\n")


def stub_case(case: dict) -> dict:
    """Deterministic fake metrics from the plant; scenario.seed selects a behaviour:
    1 raises, 2 diverges, 3 kills its worker process."""
    _log_call(case)
    scn = case["scenario"]
    if scn.seed == 1:
        raise ValueError("stub failure")
    if scn.seed == 3:
        os._exit(3)
    m = sum(scn.plant_slave.masses)
    kb = sum(scn.plant_slave.bending_stiffness)
    ke = sum(scn.plant_slave.extension_stiffness)
    values = {"e2_rms": 1e-3 * m + 1e-4 * kb + 1e-6 * ke, "e2_max": 2e-3 * m, "beta_min": 1.0 / m}
    out = {"status": "diverged" if scn.seed == 2 else "ok", "message": "stub",
           "metrics": {k: values.get(k) for k in case["metrics"]}, "wall_time": 0.0}
    if case["record"]:
        out["recording"] = f"fake rrd {case['case_id']}".encode()
    return out


def slow_stub(case: dict) -> dict:
    pids = os.environ.get(PIDS_ENV)
    if pids:
        with open(pids, "a") as fh:
            fh.write(f"{os.getpid()}\n")
    time.sleep(0.3)
    return stub_case(case)


WARM_ENV = "SWEEP_TEST_WARM"


def warm_probe(case: dict) -> dict:
    """Logs its pid and whether the case found the loop modules already imported (a forked worker
    inherits them from the parent; a spawned one starts without them), then acts as stub_case."""
    with open(os.environ[WARM_ENV], "a") as fh:
        fh.write(f"{os.getpid()} {int('harness.loop.mujoco_loop' in sys.modules)}\n")
    return stub_case(case)


# --- helpers ---------------------------------------------------------------------------------------
def study(factors: list[dict], sampling: dict | None = None, **st) -> dict:
    doc = {"study": {"name": "t", "metrics": METRICS, **st}, "factor": factors}
    if sampling:
        doc["sampling"] = sampling
    return doc


MASS = {"name": "slave_mass", "param": "plant.slave.masses", "scale": [0.5, 0.75, 1.0, 1.25, 1.5]}
GRID2 = [{"name": "bending", "param": "plant.slave.bending_stiffness", "scale": [0.5, 1.0, 1.5]},
         {"name": "extension", "param": "plant.slave.extension_stiffness", "scale": [0.5, 1.0, 1.5]}]


def table_lines(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / RESULTS).read_text().splitlines()]


@pytest.fixture
def calls(tmp_path, monkeypatch):
    path = tmp_path / "calls.txt"
    path.touch()
    monkeypatch.setenv(CALLS_ENV, str(path))
    return lambda: path.read_text().split()


# --- study parsing and expansion -------------------------------------------------------------------
def test_grid_expansion_counts():
    assert len(expand_cases(load_study(study([MASS])))) == 5
    assert len(expand_cases(load_study(study(GRID2)))) == 9
    seg = [{"param": "plant.segments", "values": [4, 8, 16]},
           {"param": "plant.actuation", "values": ["servo", "torque"]}]
    cases = expand_cases(load_study(study(seg)))
    assert len(cases) == 6
    assert {(c.scenario.plant.segments, c.scenario.plant.actuation) for c in cases} == {
        (n, a) for n in (4, 8, 16) for a in ("servo", "torque")}
    # a random factor in grid mode: every grid point x the same n draws
    mixed = [GRID2[0], {"name": "wn", "param": "plant.servo_frequency",
                        "values": {"random": "uniform", "low": 10.0, "high": 30.0}}]
    cases = expand_cases(load_study(study(mixed, {"n": 4, "seed": 1})))
    assert len(cases) == 12
    by_level = {}
    for c in cases:
        by_level.setdefault(c.params["bending"], []).append(c.params["wn"])
    assert len({tuple(v) for v in by_level.values()}) == 1  # common random numbers


def test_random_sampling_is_seeded():
    doc = study([{"name": "kb", "param": "plant.slave.bending_stiffness",
                  "scale": {"random": "uniform", "low": 0.5, "high": 1.5}},
                 {"param": "plant.segments", "values": [4, 8]}], {"mode": "random", "n": 7, "seed": 3})
    a, b = expand_cases(load_study(doc)), expand_cases(load_study(doc))
    assert [c.case_id for c in a] == [c.case_id for c in b]
    assert [c.params for c in a] == [c.params for c in b]
    assert len(a) == 7
    for c in a:
        assert 0.5 <= c.params["kb"] <= 1.5
        assert c.params["plant.segments"] in (4, 8)
        expected = [c.params["kb"] * v for v in NOMINAL.bending_stiffness]
        np.testing.assert_allclose(c.scenario.plant_slave.bending_stiffness, expected, rtol=1e-11)
    doc["sampling"]["seed"] = 4
    assert [c.params for c in expand_cases(load_study(doc))] != [c.params for c in a]


@pytest.mark.slow
def test_case_ids_stable_across_processes():
    doc = study(GRID2)
    ids = [c.case_id for c in expand_cases(load_study(doc))]
    assert len(set(ids)) == 9 and all(len(i) == 12 for i in ids)
    code = ("import json, sys; from harness.studies.sweep import load_study, expand_cases; "
            "print(json.dumps([c.case_id for c in expand_cases(load_study(json.loads(sys.argv[1])))]))")
    proc = subprocess.run([sys.executable, "-c", code, json.dumps(doc)], capture_output=True, text=True,
                          cwd=ROOT, check=True)
    assert json.loads(proc.stdout) == ids


def test_scale_applies_to_the_plant_only():
    doc = study([{"name": "m0", "param": "plant.slave.masses[0]", "scale": [2.0]},
                 {"name": "kb", "param": "plant.slave.bending_stiffness", "scale": [0.5]},
                 {"name": "l2", "param": "plant.master.lengths[1]", "values": [0.7]},
                 {"name": "snr", "param": "snr_db", "scale": [0.5]},
                 {"name": "wn", "param": "plant.servo_frequency", "scale": [2.0]},
                 {"name": "cc", "param": "plant.enforce_cc", "values": [True]}])
    (case,) = expand_cases(load_study(doc))
    scn = case.scenario
    assert scn.slave == NOMINAL and scn.master == MasterParams()  # the controller keeps its model
    ps = scn.plant_slave
    np.testing.assert_allclose(ps.masses, [2.0, 0.7, 0.4])
    np.testing.assert_allclose(ps.bending_stiffness, [4.0, 1.5, 0.5])
    assert ps.extension_stiffness == NOMINAL.extension_stiffness and ps.n_quad == NOMINAL.n_quad
    assert scn.plant.master is not None and scn.plant_master.lengths == (0.6, 0.7)
    assert scn.plant_master.masses == MasterParams().masses
    assert scn.snr_db == pytest.approx(20.0)
    assert scn.plant.servo_frequency == pytest.approx(40.0) and scn.plant.enforce_cc is True
    assert case.params == {"m0": 2.0, "kb": 0.5, "l2": 0.7, "snr": 0.5, "wn": 2.0, "cc": True}


def test_scale_is_relative_to_the_controller_model():
    # inline base: a custom nominal slave, and a plant that already differs in bending stiffness
    doc = study([{"name": "m", "param": "plant.slave.masses", "scale": [0.5]}])
    doc["scenario"] = {"slave": {"masses": [2.0, 1.0, 0.5]},
                       "plant": {"slave": {"bending_stiffness": [9.0, 4.0, 2.0]}}}
    (case,) = expand_cases(load_study(doc))
    assert case.overrides == ("plant.slave.masses=[1.0, 0.5, 0.25]",)
    scn = case.scenario
    assert scn.slave.masses == (2.0, 1.0, 0.5)  # controller model untouched
    assert scn.plant_slave.masses == (1.0, 0.5, 0.25)  # 0.5 x the controller's masses
    assert scn.plant_slave.bending_stiffness == (9.0, 4.0, 2.0)  # the base plant's own value is kept


@pytest.mark.parametrize("factor, words", [
    ({"name": "typo", "param": "plant.slave.mass", "scale": [1.0]}, ["typo", "mass"]),
    ({"name": "ctrl", "param": "slave.masses", "scale": [1.0]}, ["ctrl", "plant.slave.masses"]),
    ({"name": "neg", "param": "plant.slave.masses", "scale": [1.0, -1.0]}, ["neg", "-1.0", "masses"]),
    ({"name": "idx", "param": "plant.slave.masses[3]", "scale": [1.0]}, ["idx", "[3]"]),
    ({"name": "both", "param": "plant.segments", "scale": [1.0], "values": [4]}, ["both"]),
    ({"name": "kind", "param": "plant.kind", "scale": [2.0]}, ["kind", "values"]),
    ({"name": "odd", "param": "plant.segments", "scale": [1.1]}, ["odd", "integer"]),
])
def test_bad_study_raises_before_anything_runs(tmp_path, calls, factor, words):
    with pytest.raises(ConfigError) as err:
        run_sweep(study([factor]), out=tmp_path / "out", workers=1, progress=False, case_fn=stub_case)
    for w in words:
        assert w in str(err.value)
    assert calls() == [] and not (tmp_path / "out" / RESULTS).exists()


def test_study_file_errors(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('[study]\nmetrics = ["e2_rms", "e9"]\n[[factor]]\nparam = "snr_db"\nscale = [1.0]\n')
    with pytest.raises(ConfigError, match="e9"):
        load_study(f)
    f.write_text('[[factor]]\nparam = "snr_db"\nscale = {random = "uniform", low = 0.5, high = 1.5}\n')
    with pytest.raises(ConfigError, match="n"):
        load_study(f)  # random draws need [sampling] n
    f.write_text('[study]\nscenario = "missing.toml"\n[[factor]]\nparam = "snr_db"\nscale = [1.0]\n')
    with pytest.raises(ConfigError, match="base scenario"):
        expand_cases(load_study(f))


@pytest.mark.parametrize("name", ["mass_mismatch", "stiffness_grid", "segments"])
def test_shipped_studies_expand(name):
    cases = expand_cases(load_study(ROOT / "studies" / f"{name}.toml"))
    assert len(cases) == {"mass_mismatch": 5, "stiffness_grid": 9, "segments": 12}[name]  # 3 N x 2 modes x CC


# --- running, resuming, failures -------------------------------------------------------------------
@pytest.mark.slow
def test_resume_after_crash_runs_nothing_twice(tmp_path, calls):
    out, doc, k = tmp_path / "out", study(GRID2), 3

    def crash_after_k(row):
        if len(table_lines(out)) >= k:
            raise KeyboardInterrupt

    with pytest.raises(SweepInterrupted) as err:
        run_sweep(doc, out=out, workers=2, progress=False, case_fn=stub_case, on_row=crash_after_k)
    assert len(err.value.result.rows) == k
    first = [r["case_id"] for r in table_lines(out)]
    assert len(first) == k
    n_calls = len(calls())
    res = run_sweep(doc, out=out, workers=2, progress=False, case_fn=stub_case)
    second = calls()[n_calls:]
    assert sorted(second) == sorted(set(c.case_id for c in res.cases) - set(first))  # each exactly once
    assert res.ran == 9 - k and res.skipped == k and res.complete
    rows = table_lines(out)
    assert sorted(r["case_id"] for r in rows) == sorted(c.case_id for c in res.cases)
    # a third run finds everything done
    res = run_sweep(doc, out=out, workers=2, progress=False, case_fn=stub_case)
    assert res.ran == 0 and len(calls()) == n_calls + 9 - k


@pytest.mark.slow
def test_failing_and_diverged_cases_are_rows(tmp_path):
    doc = study([MASS, {"param": "seed", "values": [0, 1, 2]}])
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    rows = table_lines(tmp_path)
    assert len(rows) == 15 and res.complete
    by_seed = {}
    for r in rows:
        by_seed.setdefault(r["params"]["seed"], set()).add(r["status"])
    assert by_seed == {0: {"ok"}, 1: {"error"}, 2: {"diverged"}}
    err = next(r for r in rows if r["status"] == "error")
    assert "stub failure" in err["message"] and "ValueError" in err["traceback"]
    ok = next(r for r in rows if r["params"] == {"slave_mass": 1.0, "seed": 0})
    assert set(ok) == {"case_id", "params", "status", "message", "metrics", "wall_time", "traceback"}
    assert ok["metrics"]["e2_max"] == pytest.approx(2e-3 * sum(NOMINAL.masses))


@pytest.mark.slow
def test_dead_worker_is_isolated(tmp_path, calls):
    doc = study([{"param": "seed", "values": [0, 3, 4, 5, 6]}])
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    assert res.complete
    status = {r["params"]["seed"]: r for r in table_lines(tmp_path)}
    assert status[3]["status"] == "error" and "died" in status[3]["message"]
    assert all(status[s]["status"] == "ok" for s in (0, 4, 5, 6))


def test_pool_broken_between_waits_is_not_an_error(tmp_path, calls, monkeypatch):
    """A worker can die after one wait returned and before the next submit: the submit then raises
    BrokenProcessPool itself.  That case goes back to the queue, the in-flight case that died is
    isolated as usual, and every case still gets its row (regression: this used to abort the sweep)."""
    import concurrent.futures as cf
    from concurrent.futures.process import BrokenProcessPool

    import harness.studies.executor as sw

    real = sw._process_pool
    made = []

    class BreaksOnSecondSubmit(cf.Executor):
        def __init__(self):
            self.n = 0

        def submit(self, fn, /, *args, **kwargs):
            self.n += 1
            if self.n > 1:
                raise BrokenProcessPool("a child process terminated abruptly")
            fut = cf.Future()
            fut.set_exception(BrokenProcessPool("a child process terminated abruptly"))
            return fut

    def pool(workers):
        made.append(workers)
        return BreaksOnSecondSubmit() if len(made) == 1 else real(workers)

    monkeypatch.setattr(sw, "_process_pool", pool)
    doc = study([{"param": "seed", "values": [0, 4, 5]}])
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    assert res.complete
    assert all(r["status"] == "ok" for r in table_lines(tmp_path))
    assert len(made) >= 2  # the broken pool was replaced


def test_executor_failure_stops_the_sweep(tmp_path):
    # a case function the workers cannot unpickle: an executor problem, not a case result
    with pytest.raises(SweepError, match="executor failed"):
        run_sweep(study([MASS]), out=tmp_path, workers=1, progress=False, case_fn=lambda case: {})
    assert read_results(tmp_path / RESULTS) == {}  # nothing recorded: a re-run runs every case


def test_run_case_never_raises(monkeypatch):
    import types

    from harness.loop.trajectory import Trajectory

    (case,) = expand_cases(load_study(study([{"param": "seed", "values": [0]}])))
    payload = {"case_id": case.case_id, "scenario": case.scenario, "metrics": METRICS, "record": False}

    def boom(scn, progress=False, **kw):
        raise RuntimeError("solver exploded")

    def diverges(scn, progress=False, **kw):
        z = np.zeros((0, 2))
        return Trajectory(np.zeros(0), z, z, np.zeros((0, 6)), np.zeros((0, 6)), z, z, z, z, z, z, z,
                          np.zeros(0), np.zeros(0), np.zeros((0, 6)), z, np.zeros((0, 6)), np.zeros((0, 6)),
                          status="diverged", message="NaN at t=0.1")

    metrics = types.SimpleNamespace(compute_metrics=lambda traj, scn: {"e2_rms": float("nan"),
                                                                        "e2_max": np.float64(1.5)})
    monkeypatch.setitem(sys.modules, "harness.loop.metrics", metrics)
    monkeypatch.setitem(sys.modules, "harness.loop", types.SimpleNamespace(simulate=boom))
    row = run_case(payload)
    assert row["status"] == "error" and "solver exploded" in row["message"]
    assert "RuntimeError" in row["traceback"] and row["wall_time"] >= 0
    monkeypatch.setitem(sys.modules, "harness.loop", types.SimpleNamespace(simulate=diverges))
    row = run_case(payload)
    assert row["status"] == "diverged" and row["message"] == "NaN at t=0.1"
    assert row["metrics"] == {"e2_rms": None, "e2_max": 1.5, "beta_min": None}


@pytest.mark.slow
def test_torn_last_line_is_ignored(tmp_path, calls):
    doc = study([MASS])
    run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    full = (tmp_path / RESULTS).read_bytes()
    lines = full.splitlines(keepends=True)
    torn = b"".join(lines[:2]) + lines[2][:25]  # crash in the middle of writing row 3
    (tmp_path / RESULTS).write_bytes(torn)
    assert len(read_results(tmp_path / RESULTS)) == 2
    n = len(calls())
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    assert res.ran == 3 and len(calls()) == n + 3
    rows = table_lines(tmp_path)  # every line parses again
    assert sorted(r["case_id"] for r in rows) == sorted(c.case_id for c in res.cases)


@pytest.mark.slow
def test_sigterm_stops_workers_and_keeps_rows(tmp_path):
    out, pids = tmp_path / "out", tmp_path / "pids.txt"
    doc = study([{"param": "seed", "values": list(range(4, 24))}])
    script = (
        "import json, sys\n"
        f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
        "from test_sweep import slow_stub\n"
        "from harness.studies.sweep import SweepInterrupted, run_sweep\n"
        "try:\n"
        f"    run_sweep(json.loads(sys.argv[1]), out={str(out)!r}, workers=2, progress=False,"
        " case_fn=slow_stub)\n"
        "except SweepInterrupted:\n"
        "    sys.exit(1)\n")
    env = {**os.environ, PIDS_ENV: str(pids)}
    proc = subprocess.Popen([sys.executable, "-c", script, json.dumps(doc)], cwd=ROOT, env=env)
    deadline = time.monotonic() + 60
    while not ((out / RESULTS).exists() and len((out / RESULTS).read_text().splitlines()) >= 2):
        assert time.monotonic() < deadline and proc.poll() is None, "sweep did not start"
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 1
    rows = table_lines(out)
    assert 2 <= len(rows) < 20
    time.sleep(0.5)
    for pid in {int(p) for p in pids.read_text().split()}:  # workers are gone
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    res = run_sweep(doc, out=out, workers=2, progress=False, case_fn=stub_case)
    assert res.complete and res.skipped == len(rows) and len(table_lines(out)) == 20


@pytest.mark.slow
def test_dask_matches_process_pool(tmp_path, calls):
    from distributed import LocalCluster

    doc = study([MASS, {"param": "seed", "values": [0, 1, 2]}])
    pool = run_sweep(doc, out=tmp_path / "pool", workers=2, progress=False, case_fn=stub_case)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        dask = run_sweep(doc, out=tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False,
                         case_fn=stub_case)
    assert dask.complete and dask.ran == 15

    def strip(rows):
        return {r["case_id"]: {k: v for k, v in r.items() if k != "traceback"} for r in rows.values()}

    assert strip(dask.rows) == strip(pool.rows)
    assert len(calls()) == 30


# --- outputs ---------------------------------------------------------------------------------------
@pytest.mark.slow
def test_summary_plots_recordings_and_provenance(tmp_path):
    doc = study(GRID2, record={"worst": 2, "by": "e2_rms"})
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    for name in ("summary.csv", "study.toml", "metric_vs_bending.png", "metric_vs_extension.png",
                 "heatmap_bending__extension.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    csv_lines = (tmp_path / "summary.csv").read_text().splitlines()
    assert csv_lines[0] == "case_id,bending,extension,status,e2_rms,e2_max,beta_min,case_wall_time,message"
    assert len(csv_lines) == 10
    # worst 2 by e2_rms: the stiffest extension/bending combinations in the stub
    worst = sorted(res.rows.values(), key=lambda r: r["metrics"]["e2_rms"])[-2:]
    assert sorted(p.name for p in res.recordings) == sorted(f"{r['case_id']}.rrd" for r in worst)
    for r in worst:
        data = (tmp_path / "recordings" / f"{r['case_id']}.rrd").read_bytes()
        assert data == f"fake rrd {r['case_id']}".encode()
    # the written study.toml is itself a study with the same cases
    again = expand_cases(load_study(tmp_path / "study.toml"))
    assert [c.case_id for c in again] == [c.case_id for c in res.cases]


def test_random_study_plots(tmp_path):
    doc = study([{"name": "kb", "param": "plant.slave.bending_stiffness",
                  "scale": {"random": "loguniform", "low": 0.5, "high": 2.0}},
                 {"param": "plant.actuation", "values": ["servo", "torque"]}], {"mode": "random", "n": 6})
    run_sweep(doc, out=tmp_path, workers=2, progress=False, case_fn=stub_case)
    assert (tmp_path / "metric_vs_kb.png").exists()
    assert len((tmp_path / "summary.csv").read_text().splitlines()) == 7


# --- the real simulation ---------------------------------------------------------------------------
def test_metric_names_match_compute_metrics(synthetic_trajectory):
    from harness.config.scenario import Scenario
    from harness.loop.metrics import compute_metrics

    produced = compute_metrics(synthetic_trajectory(), Scenario(transient=0.0))
    assert set(METRIC_NAMES) == set(produced) - {"status", "message"}
    from harness.studies.sweep import METRIC_LABELS

    assert set(METRIC_LABELS) == set(METRIC_NAMES) and all("[" in v for v in METRIC_LABELS.values())


def test_end_to_end_analytic_plant(tmp_path):
    """Two real 0.5 s cases on the analytic plant through the default worker (`run_case`).
    Fails (does not skip) while harness.loop.common / harness.loop.metrics are missing."""
    import harness.loop.common  # noqa: F401
    import harness.loop.metrics  # noqa: F401

    doc = study([{"name": "slave_mass", "param": "plant.slave.masses", "scale": [0.9, 1.1]}],
                set=["duration=0.5", "transient=0.0", "plant.kind='analytic'"])
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False)
    assert res.complete
    for r in table_lines(tmp_path):
        assert r["status"] == "ok", r["message"] + r["traceback"]
        assert all(isinstance(r["metrics"][m], float) and np.isfinite(r["metrics"][m]) for m in METRICS)
        assert r["wall_time"] > 0


# --- fuzzing the study loader ----------------------------------------------------------------------
def test_fuzz_study_loader():
    """Random and mutated study tables: load_study + expand_cases either give cases or raise a
    one-line ConfigError, never another exception (nothing runs)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    keys = ["study", "factor", "sampling", "scenario", "name", "metrics", "set", "record", "param", "scale",
            "values", "random", "low", "high", "mode", "n", "seed", "worst", "by", "x"]
    params = ["seed", "snr_db", "plant.slave.masses", "plant.slave.masses[1]", "plant.segments", "gains.k4",
              "plant.actuation", "control_dt", "nope.key"]
    scalars = (st.none() | st.booleans() | st.integers(-5, 50)
               | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=6)
               | st.sampled_from(params + ["grid", "random", "uniform", "e2_rms"]))
    values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                          | st.dictionaries(st.sampled_from(keys), inner, max_size=4), max_leaves=14)

    def check(doc):
        try:
            cases = expand_cases(load_study(doc))
        except ConfigError as e:
            assert "\n" not in str(e) and str(e)
            return
        assert all(c.case_id for c in cases)

    @settings(max_examples=200, deadline=None)
    @given(st.dictionaries(st.sampled_from(keys), values, max_size=5))
    def random_tables(doc):
        check(doc)

    @settings(max_examples=200, deadline=None)
    @given(st.sampled_from(["study", "factor", "sampling"]), st.sampled_from(keys), values)
    def mutated(table, key, value):
        doc = study([{"param": "plant.slave.masses", "scale": [0.5, 1.0]},
                     {"param": "seed", "values": [0, 1]}], {"mode": "grid"})
        node = doc[table] if table != "factor" else doc["factor"][0]
        node[key] = value
        check(doc)

    random_tables()
    mutated()


_WARM_SCRIPT = """
import sys, threading, json
sys.path.insert(0, sys.argv[1])
import test_sweep as t
from harness.studies.sweep import run_sweep
if sys.argv[3] == "thread":  # another Python thread alive: the pool must not fork
    threading.Thread(target=threading.Event().wait, daemon=True).start()
if sys.argv[3] == "after":  # a sweep and a run's progress bars before: they leave no thread behind
    from harness.loop.common import progress_bar
    run_sweep(t.study([t.MASS]), out=sys.argv[2] + "-first", workers=2, progress=True, case_fn=t.stub_case)
    progress_bar(True, 10, "run").close()
    assert threading.active_count() == 1, threading.enumerate()
res = run_sweep(t.study([t.MASS]), out=sys.argv[2], workers=2, progress=False, case_fn=t.warm_probe)
print(json.dumps({k: v["metrics"] for k, v in sorted(res.rows.items())}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("threads, warm", [("none", 1), ("thread", 0), ("after", 1)])
def test_workers_are_forked_warm_only_from_a_single_threaded_process(tmp_path, threads, warm):
    """A sweep started from a process without other threads forks its workers after importing the loop
    (they start without interpreter start-up or imports); beside another thread it spawns them.  The
    rows are the same either way.  "after": a sweep and a progress bar earlier in the same process leave
    no thread behind (tqdm's monitor thread made every later sweep spawn), so the next sweep forks."""
    log = tmp_path / "warm.txt"
    env = {**os.environ, WARM_ENV: str(log), "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", _WARM_SCRIPT, str(ROOT / "tests"), str(tmp_path / "o"),
                          threads], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = [line.split() for line in log.read_text().splitlines()]
    assert len(lines) == 5 and {w for _, w in lines} == {str(warm)}
    assert 1 <= len({pid for pid, _ in lines}) <= 2  # the two workers, not the parent
    rows = json.loads(out.stdout.splitlines()[-1])
    expected = {c.case_id: stub_case({"case_id": c.case_id, "scenario": c.scenario, "metrics": METRICS,
                                      "record": False})["metrics"]
                for c in expand_cases(load_study(study([MASS])))}
    assert rows == expected


@pytest.mark.slow
def test_phase_timings_add_up(tmp_path, capsys, monkeypatch):
    """SweepResult.timings splits the call's wall time into set-up, cases, recordings and summary: each
    phase is measured, none is negative, they fit in the call, and the cases phase holds the cases (9
    cases of at least 0.3 s each on 3 workers: at least 0.9 s).  `teleop sweep` prints the rate."""
    doc = study(GRID2)
    t = time.perf_counter()
    res = run_sweep(doc, out=tmp_path / "a", workers=3, progress=False, case_fn=slow_stub)
    wall = time.perf_counter() - t
    ph = res.timings
    assert set(ph) == {"setup", "cases", "recordings", "summary"}
    assert all(v >= 0.0 for v in ph.values()), ph
    assert sum(ph.values()) <= wall
    assert ph["cases"] >= 0.9 and ph["summary"] > 0.0 and ph["setup"] > 0.0
    # the command's last line: the rate of the cases phase, and the other phases
    path = tmp_path / "study.toml"
    path.write_text((tmp_path / "a" / "study.toml").read_text())
    real = sweep_module.run_sweep
    monkeypatch.setattr(sweep_module, "run_sweep", lambda *a, **k: real(*a, case_fn=slow_stub, **k))
    assert sweep_module.main_sweep(path, tmp_path / "b", workers=3, progress=False) == 0
    err = capsys.readouterr().err
    pattern = r"ran 9 \(processes\) in \d+\.\d s \(\d+ cases/min; set-up \d+\.\d s, summary \d+\.\d s\)"
    assert re.search(pattern, err), err


def test_unhashable_distribution_name_is_one_line():
    """A distribution given as a non-string (``scale = {random = []}``, found by the study-file fuzz test)
    is a one-line ConfigError naming the factor, not a TypeError."""
    with pytest.raises(ConfigError, match=r"\[\[factor\]\] 'a': scale: random = \[\]; expected one of"):
        load_study({"study": {"name": "x"},
                    "factor": [{"name": "a", "param": "seed", "scale": {"random": []}}]})


def _mass_study(tmp_path, actuation):
    path = tmp_path / f"mass_{actuation}.toml"
    path.write_text(f"""
[study]
name = "mass_{actuation}"
set = ["duration=0.6", "transient=0.2", "plant.actuation='{actuation}'"]
metrics = ["e2_rms"]

[[factor]]
name = "slave_mass"
param = "plant.slave.masses"
scale = [0.5, 2.0]
""")
    return path


@pytest.mark.parametrize("actuation", ["servo", "muscle", "cosserat servo"])
def test_a_servo_plant_warns_when_a_study_varies_what_it_hides(tmp_path, capsys, caplog, actuation):
    """A study varying the slave's mass on the servo chain says so in one line before it runs and again in
    its summary with the measured spread of e2; on a plant that feels the mass (muscles, the rod's
    rest-strain servo) it says nothing."""
    from harness.studies.sweep import main_sweep

    study = _mass_study(tmp_path, actuation.split()[-1])
    if actuation.startswith("cosserat"):
        text = study.read_text().replace('set = ["', 'set = ["plant.kind=\'cosserat\'", "')
        study.write_text(text)
    rc = main_sweep(study, out=tmp_path / "o", workers=1, progress=False, executor="threads")
    assert rc == 0
    before = [r.getMessage() for r in caplog.records if "hide them" in r.getMessage()]  # logged at the start
    after = [ln for ln in capsys.readouterr().err.splitlines() if "hide them" in ln]  # in the summary
    if actuation == "servo":
        assert len(before) == 1 and "'slave_mass'" in before[0] and len(after) == 1
        assert re.search(r"measured: slave_mass: e2_rms \S+ at 0\.5 -> \S+ at 2", after[0]), after
    else:
        assert before == after == []
