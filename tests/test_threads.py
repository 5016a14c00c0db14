"""Runs in several threads of one process: the sweep's thread executor (`run_sweep(executor="threads")`,
the in-process batch path) and `simulate` called from threads.  The compiled loops release the GIL, so
what is shared between runs must be safe: the ahead-of-time modules load once, MuJoCo's process-wide warning
callback hands each warning to the run whose thread raised it, and a sweep's results are the same as with
worker processes and as single runs.  No timing assertions (benchmarks/bench_core.py measures the speed)."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.loop import common, mj_warnings, simulate
from harness.studies.executor import pick_executor
from harness.studies.sweep import RESULTS, SweepInterrupted, expand_cases, load_study, run_case, run_sweep

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "scenarios" / "paper.toml"
SHORT = ["duration=0.3", "transient=0"]
# euler, stiff servos, no material damping: MuJoCo warns (mjWARN_BADQACC) and the run stops there
# (tests/test_reliability.py)
EULER = ["plant.integrator='euler'", "plant.enforce_cc=true", "plant.bending_viscosity=[0, 0, 0]",
         "plant.extension_viscosity=[0, 0, 0]"]
WARNS = [*SHORT, *EULER, "plant.servo_frequency=40"]
METRICS = ["e2_rms", "e2_max", "beta_min", "mujoco_warnings"]


def _together(fns: list) -> list:
    """Call each fn in its own thread, released at the same moment; return their results in order."""
    out: list = [None] * len(fns)
    errors: list[BaseException] = []
    gate = threading.Barrier(len(fns))

    def run(i, fn):
        try:
            gate.wait()
            out[i] = fn()
        except BaseException as e:  # noqa: BLE001 - re-raised below, in the test's thread
            errors.append(e)

    threads = [threading.Thread(target=run, args=(i, fn)) for i, fn in enumerate(fns)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return out


def test_warnings_stay_with_the_run_that_raised_them(traj_arrays):
    """Two runs at once, one raising a MuJoCo warning and one clean: each reports only its own warning text,
    as when run alone, and the process-wide callback is removed after them."""
    warn, clean = load_scenario(PAPER, WARNS), load_scenario(PAPER, SHORT)
    ref_warn, ref_clean = simulate(warn), simulate(clean)
    assert ref_warn.status == "diverged" and ref_warn.meta["mujoco_warning_text"]
    assert ref_clean.status == "ok" and ref_clean.meta["mujoco_warning_text"] == []
    for _ in range(5):
        a, b = _together([lambda: simulate(warn), lambda: simulate(clean)])
        for got, ref in ((a, ref_warn), (b, ref_clean)):
            assert (got.status, got.message) == (ref.status, ref.message)
            assert got.meta["mujoco_warning_text"] == ref.meta["mujoco_warning_text"]
            for key, v in traj_arrays(ref).items():
                np.testing.assert_array_equal(traj_arrays(got)[key], v, err_msg=key)
    assert mj_warnings._sinks == {}


def test_a_warning_from_a_thread_running_no_loop_is_not_lost(capfd):
    """While a run captures, a warning raised in another thread (user code) goes to stderr, as MuJoCo's own
    callback would print it, not into the run."""
    with mj_warnings.warning_sink() as text:
        t = threading.Thread(target=mj_warnings._dispatch, args=("elsewhere",))
        t.start()
        t.join()
        mj_warnings._dispatch("mine")
    assert text == ["mine"]
    assert "WARNING: elsewhere" in capfd.readouterr().err


_LOAD_AT_ONCE = r"""
import logging, sys, threading
logging.basicConfig(level=logging.WARNING, stream=sys.stdout)
from harness.config.scenario import Scenario
from harness.loop import simulate
gate = threading.Barrier(3)
out = []
def run():
    gate.wait()
    out.append(simulate(Scenario(duration=0.05)).status)
ts = [threading.Thread(target=run) for _ in range(3)]
[t.start() for t in ts]
[t.join() for t in ts]
print("STATUSES", sorted(out), "numba" in sys.modules)
"""


def test_threads_load_the_compiled_module_once():
    """Three threads of a fresh process start a run at the same moment: each uses the ahead-of-time module
    (none falls back to numba's JIT).  Loading one extension module from two threads at once failed inside
    importlib before `harness.loop.aot` serialised it."""
    simulate(load_scenario(PAPER, ["duration=0.05", "transient=0"]))  # module built first
    res = subprocess.run([sys.executable, "-c", _LOAD_AT_ONCE], capture_output=True, text=True, cwd=ROOT,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "unavailable" not in res.stdout + res.stderr, res.stdout + res.stderr
    assert "STATUSES ['ok', 'ok', 'ok'] False" in res.stdout, res.stdout + res.stderr


_NAMESPACE_AT_ONCE = r"""
import threading
from harness.loop import fast
gate = threading.Barrier(3)
out = []
def run():
    gate.wait()
    out.append(id(fast.kernels()))
ts = [threading.Thread(target=run) for _ in range(3)]
[t.start() for t in ts]
[t.join() for t in ts]
print("NAMESPACES", len(set(out)))
print("DEFAULT_IS_JIT", fast.kernels(True) is fast.kernels())
fast.K.desired
print("K_KEPT", fast.K.__dict__.get("desired") is fast.kernels().desired)
"""


def test_threads_build_one_kernel_namespace():
    """Three threads of a fresh process ask for the jitted kernels at once (the Python-stepped loop's first
    run): they get one namespace, the same as `kernels(True)`.  Before `harness.loop.fast.kernels` took a
    lock each built its own (3 of 3 runs), and one could compile before numba's extensions were
    registered."""
    res = subprocess.run([sys.executable, "-c", _NAMESPACE_AT_ONCE], capture_output=True, text=True,
                         cwd=ROOT, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "NAMESPACES 1" in res.stdout, res.stdout + res.stderr
    # the default namespace is the compiled one (aot.build asks for kernels(True)): not a second namespace
    assert "DEFAULT_IS_JIT True" in res.stdout, res.stdout
    # K keeps each kernel after its first access (later accesses skip __getattr__: per-step calls)
    assert "K_KEPT True" in res.stdout, res.stdout


def test_thread_sweep_of_python_stepped_cases_equals_single_runs(tmp_path, caplog):
    """Cases that hold the GIL (the Cosserat rod; a Python controller) still give the single runs' rows in
    threads (they only take turns), and the sweep says so."""
    metrics = ["e2_rms", "e2_max"]
    doc = {"study": {"name": "stepped", "metrics": metrics, "set": ["duration=0.05", "transient=0"]},
           "factor": [{"name": "case", "param": "plant.kind", "values": ["cosserat", "analytic"]},
                      {"name": "ctrl", "param": "controller", "values": ["paper", "paper_no_null"]}]}
    with caplog.at_level(logging.WARNING, logger="harness.studies.executor"):
        res = run_sweep(doc, out=tmp_path, workers=2, progress=False, executor="threads")
    assert "3 of 4 cases run a Python-stepped plant or controller" in caplog.text
    assert res.complete
    for case in res.cases:
        row = res.rows[case.case_id]
        single = run_case({"case_id": case.case_id, "scenario": case.scenario, "metrics": metrics,
                           "record": False})
        assert row["status"] == single["status"] == "ok", row["message"] + row["traceback"]
        assert row["metrics"] == single["metrics"], case.case_id


def _study(**st) -> dict:
    masses = [0.8, 0.9, 1.0, 1.1, 1.2, 1.3]
    return {"study": {"name": "threads", "metrics": METRICS, "set": [*SHORT, *EULER], **st},
            "factor": [{"name": "slave_mass", "param": "plant.slave.masses", "scale": masses},
                       {"name": "servo", "param": "plant.servo_frequency", "values": [2.0, 40.0]}]}


def _rows(out: Path) -> dict[str, dict]:
    import json

    return {r["case_id"]: r for r in map(json.loads, (out / RESULTS).read_text().splitlines())}


@pytest.mark.slow
def test_thread_sweep_equals_process_sweep_and_single_runs(tmp_path):
    """12 MuJoCo cases (some warn and stop) through 2 threads and through 2 worker processes: the same
    statuses, messages and metrics, bit for bit, and the same as `run_case` alone on each case; the worst
    case's recording is written by a thread too."""
    doc = _study(record={"worst": 1, "by": "e2_rms"})
    threads = run_sweep(doc, out=tmp_path / "threads", workers=2, progress=False, executor="threads")
    procs = run_sweep(doc, out=tmp_path / "procs", workers=2, progress=False, executor="processes")
    assert (threads.executor, procs.executor) == ("threads", "processes")
    assert threads.complete and procs.complete
    a, b = _rows(tmp_path / "threads"), _rows(tmp_path / "procs")
    assert a.keys() == b.keys() == {c.case_id for c in threads.cases}
    statuses = {r["status"] for r in a.values()}
    assert statuses == {"ok", "diverged"}, statuses  # both kinds of case ran at once
    for cid, ra in a.items():
        assert (ra["status"], ra["message"], ra["metrics"]) == (b[cid]["status"], b[cid]["message"],
                                                                 b[cid]["metrics"]), cid
    for case in threads.cases:
        single = run_case({"case_id": case.case_id, "scenario": case.scenario, "metrics": METRICS,
                           "record": False})
        row = a[case.case_id]
        assert (single["status"], single["message"], single["metrics"]) == (row["status"], row["message"],
                                                                              row["metrics"]), case.case_id
    assert [p.name for p in threads.recordings] == [p.name for p in procs.recordings]
    assert all(p.stat().st_size > 0 for p in threads.recordings)


@pytest.mark.slow
def test_an_interrupted_thread_sweep_stops_its_cases_and_resumes(tmp_path):
    """Ctrl-C (here: KeyboardInterrupt from on_row) during a thread sweep: the running cases stop at their
    next chunk, no case thread is left, the stop flag is cleared, only finished cases are rows, and the same
    call resumes to the full table."""
    doc = _study(set=[*SHORT, *EULER, "duration=2.0"])

    def stop_after_first(row):
        raise KeyboardInterrupt

    with pytest.raises(SweepInterrupted) as err:
        run_sweep(doc, out=tmp_path, workers=2, progress=False, executor="threads", on_row=stop_after_first)
    assert len(err.value.result.rows) == 1
    assert not [t for t in threading.enumerate() if t.name.startswith("sweep-case")]
    assert not common.STOP.is_set()
    assert len(_rows(tmp_path)) == 1
    res = run_sweep(doc, out=tmp_path, workers=2, progress=False, executor="threads")
    assert res.complete and res.skipped == 1 and res.ran == 11


def test_executor_choice_is_checked(caplog):
    cases = expand_cases(load_study(_study()))
    assert pick_executor("threads", None, cases) == "threads"
    assert pick_executor("processes", "tcp://x:1", cases) == "dask"
    with pytest.raises(ConfigError, match="executor.*one of processes, threads"):
        pick_executor("fibers", None, cases)
    with pytest.raises(ConfigError, match="cannot be combined with --scheduler"):
        pick_executor("threads", "tcp://x:1", cases)
    rod = expand_cases(load_study({**_study(), "factor": [
        {"param": "plant.kind", "values": ["mujoco", "cosserat"]}]}))
    with caplog.at_level(logging.WARNING, logger="harness.studies.executor"):
        pick_executor("threads", None, rod)
    assert "1 of 2 cases run a Python-stepped plant" in caplog.text


def test_cli_rejects_an_unknown_executor(tmp_path, capsys):
    from harness.cli import main

    rc = main(["sweep", str(ROOT / "studies" / "controllers.toml"), "--executor", "fibers", "--out",
               str(tmp_path / "o")])
    assert rc == 2
    assert "argument --executor: invalid choice: 'fibers'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()



def test_cli_offers_the_executors_run_sweep_accepts(capsys):
    """`teleop sweep --executor` accepts exactly the executor's own EXECUTORS (the parser does not import
    the executor module, so it lists them itself)."""
    import re

    from harness.cli.parser import build_parser
    from harness.studies.executor import EXECUTORS

    parser = build_parser()
    for name in EXECUTORS:
        assert parser.parse_args(["sweep", "study.toml", "--executor", name]).executor == name
    with pytest.raises(SystemExit):
        parser.parse_args(["sweep", "study.toml", "--executor", "no-such-executor"])
    offered = re.search(r"--executor: invalid choice: .*?\(choose from ([^)]*)\)", capsys.readouterr().err)
    assert set(re.findall(r"[\w-]+", offered.group(1))) == set(EXECUTORS)
