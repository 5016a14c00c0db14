"""End to end: what a user waits for, against raw MuJoCo (issue: speed end to end).

    .venv/bin/python benchmarks/bench_e2e.py            # paper run x3; sweeps of 16 and 64 cases x 2 s, x2
    .venv/bin/python benchmarks/bench_e2e.py --quick    # 5 s scenario, 6 cases x 1 s, 1 repetition
    .venv/bin/python benchmarks/bench_e2e.py --set duration=100 --reps 2 --no-sweep   # a longer run

Reports, in one run:
  run     `teleop run` of the scenario with every output, in a fresh process (python -m harness.cli),
          wall time split into start-up (interpreter, imports, scenario validation, config.toml),
          simulate (plant build + kernel load: the ahead-of-time module, harness.loop.aot, + loop + recording
          geometry), of which the loop,
          metrics, the wait for the rerun/matplotlib imports that run in a thread during simulate,
          the outputs (run.rrd in a forked child, the figures split between a second child and the
          process, at the same time; each writer's own wall time is given) and the rest; against raw
          mj_step of the same physics steps (benchmarks/bench_loop.py's compiled replay of the run's
          logged commands, no Python in the loop).  Each repetition runs raw, e2e, raw back to back;
          ratios are per repetition, against the mean of its two raw replays.
  sweep   cases/min of a mass study (benchmarks/bench_sweep.py's make_study) through
          `harness.studies.sweep.run_sweep` in a fresh process with 1 and 2 worker processes, and 1 and
          2 threads (`executor="threads"`, the in-process batch path) (wall
          time includes imports, worker start-up and the summary), and per-case wall and CPU time
          inside the workers: wall / CPU > 1 means the worker waited for a core (other processes),
          CPU growing with 2 workers means the two slow each other (caches, memory, frequency); the
          steady-state rate (cases after each worker's first) is what a long sweep approaches.
Prints markdown; with --write replaces benchmarks/results/bench_e2e.md.  Asserts nothing.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import datetime
import json
import multiprocessing
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_loop import _machine, logged_run, raw_replay_s  # noqa: E402
from bench_sweep import make_study  # noqa: E402

# Runs `teleop run` (harness.cli.main) in this fresh process with timers around its phases; prints JSON.
# Times are perf_counter() stamps relative to the process start (CLOCK_MONOTONIC: comparable between the
# process and its forked writer children, which append their own stamps to the file $BENCH_E2E_TIMES).
_CHILD = r"""
import json, os, sys, time
t_start = time.perf_counter()
import harness.cli as cli
assert "mujoco" not in sys.modules  # prepare_process must come first, as in `teleop`
cli.prepare_process()  # as `teleop` does (harness.cli.entry): MUJOCO_GL, the collector thresholds
from harness import api
import harness.loop as loop_pkg
import harness.output.prefetch as prefetch
stamps = {"imported": time.perf_counter() - t_start, "pid": os.getpid()}
TIMES = os.environ["BENCH_E2E_TIMES"]

def rel():
    return time.perf_counter() - t_start

def timed(mod, name, key, to_file=False):
    real = getattr(mod, name)
    def wrapper(*a, **k):
        t0 = rel()
        try:
            return real(*a, **k)
        finally:
            t1 = rel()
            if to_file:  # may run in a forked writer child: append to the shared file
                with open(TIMES, "a") as f:
                    f.write(json.dumps({"key": key, "pid": os.getpid(), "t0": t0, "t1": t1,
                                        "names": list(k.get("names") or [])}) + "\n")
            else:
                stamps[key + "_t0"], stamps[key + "_t1"] = t0, t1
    setattr(mod, name, wrapper)

real_import_all = prefetch._import_all
def import_all(names):
    t0 = rel()
    real_import_all(names)
    stamps["prefetch_t0"], stamps["prefetch_t1"] = t0, rel()
    import harness.output.plots as plots, harness.output.record as record
    timed(record, "write_recording", "recording", to_file=True)
    timed(plots, "write_figures", "figures", to_file=True)
prefetch._import_all = import_all
timed(loop_pkg, "simulate", "simulate")
import harness.loop.metrics as metrics_mod
timed(metrics_mod, "compute_metrics", "metrics")
timed(api, "_write_outputs", "outputs")
info = {}
real_run_scenario = api.run_scenario
def run_scenario(scn, *a, **k):
    stamps["run_t0"] = rel()
    res = real_run_scenario(scn, *a, **k)
    stamps["run_t1"] = rel()
    info["loop"] = res.traj.meta["wall_time"]
    info["steps"] = len(res.traj)
    info["status"] = res.traj.status
    info["failures"] = res.failures
    return res
api.run_scenario = run_scenario
from harness.config import runtime
rc = cli.main(sys.argv[1:])
stamps["end"] = rel()
print("E2E-JSON " + json.dumps({"rc": rc, "stamps": stamps, **info}))
runtime.fast_exit(rc)  # as `teleop` does (harness.cli.entry)
"""


def e2e_once(args_run: list[str]) -> dict:
    """One `teleop run` in a fresh process: {"stamps": {...}, "writers": [...], "wall", "cpu", "loop", ...};
    "wall" = the whole process from outside, "cpu" = the OS accounting of it and its writer children."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.NamedTemporaryFile("w+", suffix=".jsonl", delete=False) as tf:
        times = tf.name
    try:
        t = time.perf_counter()
        res = subprocess.run([sys.executable, "-c", _CHILD, "run", *args_run], capture_output=True, text=True,
                             cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT), "BENCH_E2E_TIMES": times})
        wall = time.perf_counter() - t
        writers = [json.loads(ln) for ln in Path(times).read_text().splitlines() if ln.strip()]
    finally:
        os.unlink(times)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("E2E-JSON ")]
    if not line:
        raise RuntimeError(f"teleop run failed: {res.stdout[-2000:]}{res.stderr[-2000:]}")
    d = json.loads(line[-1][9:])
    if d["rc"] != 0 or d.get("failures"):
        raise RuntimeError(f"teleop run exit code {d['rc']}, failures {d.get('failures')}: "
                           f"{res.stderr[-2000:]}")
    d["writers"] = writers
    d["wall"] = wall
    d["cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return d


KEYS = ["total", "raw", "startup", "simulate", "loop", "metrics", "prefetch", "prefetch_wait", "outputs",
        "recording", "figures_child", "figures_parent", "rest"]
LABELS = {"total": "**total (fresh process)**",
          "raw": "raw mj_step, same physics steps (mean of a replay before and one after the run)",
          "startup": "start-up: interpreter, imports, scenario validation, config.toml",
          "simulate": "simulate: plant build, kernel load, loop, recording geometry",
          "loop": "&nbsp;&nbsp;of which the loop",
          "metrics": "metrics",
          "prefetch": "(rerun + matplotlib imports, in a thread during simulate)",
          "prefetch_wait": "waiting for those imports after simulate",
          "outputs": "outputs: run.rrd and figures at the same time (3 processes)",
          "recording": "&nbsp;&nbsp;run.rrd, forked child (geometry at the default rate)",
          "figures_child": "&nbsp;&nbsp;figures, forked child",
          "figures_parent": "&nbsp;&nbsp;figures, this process",
          "rest": "rest (metrics.json, summary, interpreter start and exit)"}
IN_TOTAL = ("startup", "simulate", "metrics", "prefetch_wait", "outputs", "rest")  # these add up to total


def _split(d: dict) -> dict:
    st = d["stamps"]
    x = {"total": d["wall"], "startup": st["simulate_t0"], "simulate": st["simulate_t1"] - st["simulate_t0"],
         "loop": d["loop"], "metrics": st.get("metrics_t1", 0.0) - st.get("metrics_t0", 0.0),
         "prefetch": st.get("prefetch_t1", 0.0) - st.get("prefetch_t0", 0.0),
         "prefetch_wait": max(0.0, st.get("prefetch_t1", 0.0) - st["simulate_t1"]),
         "outputs": st.get("outputs_t1", 0.0) - st.get("outputs_t0", 0.0)}
    for w in d["writers"]:
        dur = w["t1"] - w["t0"]
        if w["key"] == "recording":
            x["recording"] = dur
        elif w["pid"] == st["pid"]:  # drawn by the run's process, the other group by the figure child
            x["figures_parent"] = dur
        else:
            x["figures_child"] = dur
    x["rest"] = x["total"] - sum(x.get(k, 0.0) for k in IN_TOTAL)
    return x


def run_table(scenario: str, overrides: list[str], reps: int, out) -> dict:
    from harness.api import load_scenario

    scn = load_scenario(scenario, overrides)
    tr, log = logged_run(scn)  # also warms the numba cache
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-e2e-") as tmp:
        cli_args = [scenario, "--out", str(Path(tmp) / "run"), "--no-progress"]
        for o in overrides:
            cli_args += ["--set", o]
        for _ in range(reps):
            c0 = time.process_time()
            raw = raw_replay_s(scn, log)
            raw_cpu = time.process_time() - c0  # includes the plant build of the replay (~10 ms)
            d = e2e_once(cli_args)
            w = _split(d)
            w["raw"] = 0.5 * (raw + raw_replay_s(scn, log))  # before and after: the machine drifts
            rows.append({"wall": w, "cpu": d["cpu"], "raw_cpu": raw_cpu, "steps": d["steps"],
                         "status": d["status"]})

    def stat(k):
        v = [r["wall"].get(k, 0.0) for r in rows]
        return float(np.median(v)), min(v), max(v)

    out(f"`teleop run {scenario}`{''.join(' --set ' + o for o in overrides)} ({rows[0]['steps']} steps, "
        f"status {rows[0]['status']}), {reps} repetition(s), wall seconds, median [min, max]; the rows "
        f"not in brackets or indented add up to the total:\n")
    out("| phase | wall s | / raw |")
    out("|---|---|---|")
    raw_m = stat("raw")[0]
    for k in KEYS:
        m, lo, hi = stat(k)
        out(f"| {LABELS[k]} | {m:.2f} [{lo:.2f}, {hi:.2f}] | {m / raw_m:.2f}x |")
    ratio = [r["wall"]["total"] / r["wall"]["raw"] for r in rows]
    fixed = [r["wall"]["total"] - 1.5 * r["wall"]["raw"] for r in rows]
    loop = [r["wall"]["loop"] / r["wall"]["raw"] for r in rows]
    cpu = [r["cpu"] for r in rows]
    out(f"\ntotal / raw per pair {np.median(ratio):.2f}x [{min(ratio):.2f}, {max(ratio):.2f}]; loop / raw "
        f"{np.median(loop):.2f}x [{min(loop):.2f}, {max(loop):.2f}]; goal total <= 1.5 x raw + 1.5 s: "
        f"total - 1.5 x raw = {np.median(fixed):.2f} s [{min(fixed):.2f}, {max(fixed):.2f}] (goal <= 1.5 s). "
        f"CPU of the whole command (process + writer children) {np.median(cpu):.2f} s "
        f"[{min(cpu):.2f}, {max(cpu):.2f}].\n")
    return {"rows": rows}


# ---------------------------------------------------------------------------------------------
def _timed_case(payload: dict) -> dict:
    """run_case plus the worker's CPU time and its worker (pid, thread) (diagnostic pools below)."""
    import threading

    from harness.studies.executor import run_case

    c0, w0 = time.thread_time(), time.perf_counter()
    res = run_case(payload)
    return {"worker": (os.getpid(), threading.get_ident()), "cpu": time.thread_time() - c0,
            "wall": time.perf_counter() - w0, "status": res["status"], "t_end": time.time()}


_SWEEP_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import harness.cli as cli
cli.prepare_process()  # as `teleop sweep` does (harness.cli.entry); the workers inherit MUJOCO_GL
from harness.studies.sweep import run_sweep
t1 = time.perf_counter()
res = run_sweep(json.loads(sys.argv[1]), out=sys.argv[2], workers=int(sys.argv[3]), progress=False,
                executor=sys.argv[4])
print("SWEEP-JSON " + json.dumps({"in_process": time.perf_counter() - t0, "imports": t1 - t0,
                                  "n": len(res.rows), "statuses": res.counts(), "timings": res.timings}))
from harness.config.runtime import fast_exit
fast_exit(0)  # as `teleop sweep` does (harness.cli.entry)
"""


def sweep_once(doc: dict, workers: int, n_cases: int, executor: str) -> tuple[float, dict]:
    """Wall time of one sweep in a fresh process (what `teleop sweep` costs: its imports, the pool's
    start-up, the cases, results.jsonl, summary.csv and the summary plot), and its phases: "start-up"
    (interpreter and imports), `SweepResult.timings` ("setup", "cases", "summary") and "rest" (exit)."""
    with tempfile.TemporaryDirectory(prefix="bench-e2e-sweep-") as tmp:
        t = time.perf_counter()
        res = subprocess.run([sys.executable, "-c", _SWEEP_CHILD, json.dumps(doc), str(Path(tmp) / "out"),
                              str(workers), executor], capture_output=True, text=True, cwd=ROOT,
                             env={**os.environ, "PYTHONPATH": str(ROOT)})
        wall = time.perf_counter() - t
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("SWEEP-JSON ")]
    d = json.loads(line[-1][11:]) if line else {}
    if d.get("statuses", {}).get("ok") != n_cases:
        raise RuntimeError(f"sweep failed: {res.stdout[-2000:]}{res.stderr[-2000:]}")
    t = d["timings"]
    phases = {"start-up": wall - d["in_process"] + d["imports"], "setup": t["setup"], "cases": t["cases"],
              "summary": t["summary"] + t["recordings"]}
    phases["rest"] = wall - sum(phases.values())
    return wall, phases


def _diag(case_list, w: int, executor: str) -> tuple[float, float, float]:
    """The same cases through a plain pool of w workers (spawned processes, or threads of a fresh process):
    (median wall of each worker's first case, median wall and CPU of the later cases) in the workers."""
    payloads = [{"case_id": c.case_id, "scenario": c.scenario, "metrics": ["e2_rms"], "record": False}
                for c in case_list]
    if executor == "threads":
        with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
            diag = ex.submit(_thread_diag, payloads, w).result()
    else:
        with cf.ProcessPoolExecutor(w, mp_context=multiprocessing.get_context("spawn")) as ex:
            diag = list(ex.map(_timed_case, payloads))
    first, later = {}, []
    for d in diag:
        if d["worker"] not in first:
            first[d["worker"]] = d
        else:
            later.append(d)
    fw = float(np.median([d["wall"] for d in first.values()]))
    lw = float(np.median([d["wall"] for d in later])) if later else float("nan")
    lc = float(np.median([d["cpu"] for d in later])) if later else float("nan")
    return fw, lw, lc


def _thread_diag(payloads: list[dict], w: int) -> list[dict]:
    with cf.ThreadPoolExecutor(w) as ex:
        return list(ex.map(_timed_case, payloads))


def sweep_table(cases: int, duration: float, counts: list[int], reps: int, out) -> None:
    from harness.studies.cases import expand_cases
    from harness.studies.study import load_study

    doc = make_study(cases, duration, "mujoco")
    case_list = expand_cases(load_study(doc))
    runs = [(e, w) for e in ("processes", "threads") for w in counts]
    walls: dict[tuple, list[float]] = {r: [] for r in runs}
    phases: dict[tuple, list[dict]] = {r: [] for r in runs}
    diags: dict[tuple, list[tuple]] = {r: [] for r in runs}
    for _ in range(reps):  # interleaved: 1, 2, 1, 2, ...
        for e, w in runs:
            wall, ph = sweep_once(doc, w, len(case_list), e)
            walls[e, w].append(wall)
            phases[e, w].append(ph)
            diags[e, w].append(_diag(case_list, w, e))
    out(f"Sweep: {cases} cases x {duration:g} s (mass study of benchmarks/bench_sweep.py), MuJoCo plant, "
        f"each sweep in a fresh process (`run_sweep`, the pool's spawn start-up, results and the summary "
        f"plot included; `processes`: the default worker processes, `threads`: `--executor threads`, the "
        f"in-process batch path), {reps} interleaved repetition(s), median [min, max].  'Steady state' = "
        f"workers / the median wall time of a case that is not its worker's first (a plain pool of the same "
        f"kind, same cases, run after each sweep).\n")
    out("| executor | workers | wall s | cases/min | vs 1 worker | first case per worker (wall) "
        "| later cases: wall / CPU per case | steady state cases/min | vs 1 worker |")
    out("|---|---|---|---|---|---|---|---|---|")
    base: dict[str, float] = {}
    base_ss: dict[str, float] = {}
    for e, w in runs:
        wall = float(np.median(walls[e, w]))
        rate = 60.0 * len(case_list) / wall
        base.setdefault(e, rate)
        fw, lw, lc = (float(np.median([d[i] for d in diags[e, w]])) for i in range(3))
        ss = 60.0 * w / lw
        base_ss.setdefault(e, ss)
        out(f"| {e} | {w} | {wall:.2f} [{min(walls[e, w]):.2f}, {max(walls[e, w]):.2f}] | {rate:.0f} "
            f"| {rate / base[e]:.2f}x | {fw:.2f} s | {lw:.3f} s / {lc:.3f} s | {ss:.0f} "
            f"| {ss / base_ss[e]:.2f}x |")
    out("\nWhere each sweep's wall time goes, median seconds per phase (start-up: the interpreter and "
        "the imports; set-up: the study, its cases, the output folder and the workers' start; cases: first "
        "submit to last result; summary: summary.csv and the plot, with the wait for matplotlib, imported "
        "in a thread during the cases; rest: exit).  The cases phase alone gives the rate the workers "
        "reach; the other phases do not shrink with more workers.\n")
    names = ("start-up", "setup", "cases", "summary", "rest")
    out("| executor | workers | " + " | ".join(names) + " | cases phase: cases/min | vs 1 worker |")
    out("|---|---|" + "---|" * (len(names) + 2))
    base_c: dict[str, float] = {}
    for e, w in runs:
        med = {k: float(np.median([p[k] for p in phases[e, w]])) for k in names}
        crate = 60.0 * len(case_list) / med["cases"]
        base_c.setdefault(e, crate)
        out(f"| {e} | {w} | " + " | ".join(f"{med[k]:.2f}" for k in names)
            + f" | {crate:.0f} | {crate / base_c[e]:.2f}x |")
    out("")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="5 s scenario, 6 cases x 1 s, 1 repetition")
    ap.add_argument("--reps", type=int, default=None, help="repetitions of the run (default 3; quick 1)")
    ap.add_argument("--cases", default=None, help="sweep sizes, comma-separated (default 16,64; quick 6)")
    ap.add_argument("--no-sweep", action="store_true", help="skip the sweep table")
    ap.add_argument("--no-run", action="store_true", help="skip the `teleop run` table")
    ap.add_argument("--sweep-reps", type=int, default=None,
                    help="repetitions of each sweep (default 2; quick 1)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override for the run (repeatable), e.g. --set duration=100")
    ap.add_argument("--write", action="store_true", help="replace benchmarks/results/bench_e2e.md")
    args = ap.parse_args()
    lines: list[str] = []

    def out(s: str = "") -> None:
        print(s, flush=True)
        lines.append(s)

    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    load = os.getloadavg()
    out(f"## End to end: `teleop run` and sweeps ({now})\n")
    out(f"Machine: {_machine()}; load average at start {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
        f"(1/5/15 min) on {os.cpu_count()} CPUs: figures measured under that load.\n")
    overrides = (["duration=5", "transient=1"] if args.quick else []) + args.overrides
    if not args.no_run:
        run_table("scenarios/paper.toml", overrides, args.reps or (1 if args.quick else 3), out)
    if not args.no_sweep:
        sizes = [int(c) for c in (args.cases or ("6" if args.quick else "16,64")).split(",")]
        for n in sizes:
            sweep_table(n, 1.0 if args.quick else 2.0, sorted({1, 2, os.cpu_count() or 1}),
                        args.sweep_reps or (1 if args.quick else 2), out)
    load = os.getloadavg()
    out(f"Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}.\n")
    if args.write:
        from results import write_result

        write_result(__file__, "\n".join(lines))


if __name__ == "__main__":
    main()
