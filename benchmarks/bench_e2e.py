"""End to end: what a user waits for, against raw MuJoCo (issue: speed end to end).

    .venv/bin/python benchmarks/bench_e2e.py            # paper scenario (20 s), sweep 8 cases x 2 s
    .venv/bin/python benchmarks/bench_e2e.py --quick    # 5 s scenario, 6 cases x 1 s, 1 repetition

Reports, in one run:
  run     `teleop run` of the scenario with every output, in a fresh process (python -m harness.cli),
          wall time split into start-up (interpreter, imports, scenario validation), simulate
          (plant build + numba kernel load + loop + recording geometry), of which the loop, metrics,
          recording (run.rrd at the default geometry rate), figures (5 PNGs) and the rest; against
          raw mj_step of the same physics steps (benchmarks/bench_loop.py's compiled replay of the
          run's logged commands, no Python in the loop).  Each repetition runs raw then e2e back to
          back; ratios are per pair.
  sweep   cases/min of the same small mass study (benchmarks/bench_sweep.py's make_study) through
          `harness.studies.sweep.run_sweep` with 1 and 2 worker processes (wall time includes worker
          start-up), and per-case wall and CPU time inside the workers for both: wall / CPU > 1 means
          the worker waited for a core (other processes), CPU growing with 2 workers means the two
          slow each other (caches, memory, frequency).
Prints markdown; with --write appends the tables to benchmarks/RESULTS.md.  Asserts nothing.
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
_CHILD = r"""
import json, sys, time
t_start, c_start = time.perf_counter(), time.process_time()
import harness.cli as cli
from harness import api
import harness.loop as loop_pkg
t_imported, c_imported = time.perf_counter(), time.process_time()
phases, cpu = {}, {}

def timed(mod, name, key):
    real = getattr(mod, name)
    def wrapper(*a, **k):
        t, c = time.perf_counter(), time.process_time()
        try:
            return real(*a, **k)
        finally:
            phases[key] = phases.get(key, 0.0) + time.perf_counter() - t
            cpu[key] = cpu.get(key, 0.0) + time.process_time() - c
    setattr(mod, name, wrapper)

timed(loop_pkg, "simulate", "simulate")
import harness.loop.metrics as metrics_mod
timed(metrics_mod, "compute_metrics", "metrics")
real_run_scenario = api.run_scenario
info = {}
def run_scenario(scn, *a, **k):
    phases["until_run"], cpu["until_run"] = time.perf_counter() - t_start, time.process_time() - c_start
    t, c = time.perf_counter(), time.process_time()
    import harness.output.plots as plots, harness.output.record as record  # api imports them anyway
    phases["output_imports"], cpu["output_imports"] = time.perf_counter() - t, time.process_time() - c
    timed(record, "write_recording", "recording")
    timed(plots, "write_figures", "figures")
    res = real_run_scenario(scn, *a, **k)
    info["loop"] = res.traj.meta["wall_time"]
    info["steps"] = len(res.traj)
    info["status"] = res.traj.status
    return res
api.run_scenario = run_scenario
rc = cli.main(sys.argv[1:])
phases["total_in_process"] = time.perf_counter() - t_start
cpu["total_in_process"] = time.process_time() - c_start
phases["imports"], cpu["imports"] = t_imported - t_start, c_imported - c_start
print("E2E-JSON " + json.dumps({"rc": rc, "wall": phases, "cpu": cpu, **info}))
"""

def e2e_once(args_run: list[str]) -> dict:
    """One `teleop run` in a fresh process: {"wall": {phase: s}, "cpu": {phase: s}, "loop", "steps", ...};
    "total" = the whole process (wall from outside; CPU from the OS accounting of the reaped child)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", _CHILD, "run", *args_run], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("E2E-JSON ")]
    if not line:
        raise RuntimeError(f"teleop run failed: {res.stdout[-2000:]}{res.stderr[-2000:]}")
    d = json.loads(line[-1][9:])
    d["wall"]["total"] = wall
    d["cpu"]["total"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return d


KEYS = ["total", "raw", "startup", "simulate", "metrics", "output_imports", "recording", "figures", "rest"]
LABELS = {"total": "**total (fresh process)**", "raw": "raw mj_step, same physics steps",
          "startup": "start-up: interpreter, imports, scenario validation",
          "simulate": "simulate: plant build, numba kernel load, loop, recording geometry",
          "metrics": "metrics", "output_imports": "imports of rerun + matplotlib (when outputs are written)",
          "recording": "run.rrd (geometry at the default rate)", "figures": "figures (5 PNGs)",
          "rest": "rest (config.toml, metrics.json, summary, interpreter exit)"}


def _split(d: dict, kind: str) -> dict:
    x = dict(d[kind])
    x["startup"] = x["until_run"] + (x["total"] - x["total_in_process"])  # + interpreter start and exit
    x["rest"] = x["total"] - sum(x.get(k, 0.0) for k in ("startup", "simulate", "metrics", "output_imports",
                                                           "recording", "figures"))
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
            w, c = _split(d, "wall"), _split(d, "cpu")
            w["raw"], c["raw"] = raw, raw_cpu
            rows.append({"wall": w, "cpu": c, "loop": d["loop"], "steps": d["steps"], "status": d["status"]})

    def stat(kind, k):
        v = [r[kind].get(k, 0.0) for r in rows]
        return float(np.median(v)), min(v), max(v)

    out(f"`teleop run {scenario}`{''.join(' --set ' + o for o in overrides)} ({rows[0]['steps']} steps, "
        f"status {rows[0]['status']}), {reps} repetition(s), seconds, median [min, max]:\n")
    out("| phase | wall | CPU | CPU / raw CPU |")
    out("|---|---|---|---|")
    raw_c = stat("cpu", "raw")[0]
    for k in KEYS:
        (wm, wl, wh), (cm, cl, ch) = stat("wall", k), stat("cpu", k)
        out(f"| {LABELS[k]} | {wm:.2f} [{wl:.2f}, {wh:.2f}] | {cm:.2f} [{cl:.2f}, {ch:.2f}] "
            f"| {cm / raw_c:.2f}x |")
        if k == "simulate":
            lw = [r["loop"] for r in rows]
            out(f"| &nbsp;&nbsp;of which the loop (wall) | {np.median(lw):.2f} "
                f"[{min(lw):.2f}, {max(lw):.2f}] | | |")
    for kind in ("wall", "cpu"):
        ratio = [r[kind]["total"] / r[kind]["raw"] for r in rows]
        fixed = [r[kind]["total"] - 1.5 * r[kind]["raw"] for r in rows]
        out(f"\n{kind}: total / raw per pair {np.median(ratio):.2f}x [{min(ratio):.2f}, {max(ratio):.2f}]; "
            f"goal total <= 1.5 x raw + 1.5 s: total - 1.5 x raw = {np.median(fixed):.2f} s "
            f"[{min(fixed):.2f}, {max(fixed):.2f}]")
    out("")
    return {"rows": rows}


# ---------------------------------------------------------------------------------------------
def _timed_case(payload: dict) -> dict:
    """run_case plus the worker's CPU time and pid (diagnostic pool below)."""
    from harness.studies.executor import run_case

    c0, w0 = time.process_time(), time.perf_counter()
    res = run_case(payload)
    return {"pid": os.getpid(), "cpu": time.process_time() - c0, "wall": time.perf_counter() - w0,
            "status": res["status"], "t_end": time.time()}


def sweep_table(cases: int, duration: float, counts: list[int], out) -> None:
    from harness.studies.cases import expand_cases
    from harness.studies.study import load_study
    from harness.studies.sweep import run_sweep

    doc = make_study(cases, duration, "mujoco")
    case_list = expand_cases(load_study(doc))
    out(f"Sweep: {cases} cases x {duration:g} s (mass study of benchmarks/bench_sweep.py), MuJoCo plant.\n")
    out("| workers | wall s | cases/min | vs 1 worker | first case per worker (wall) "
        "| later cases: wall / CPU per case |")
    out("|---|---|---|---|---|---|")
    base = None
    for w in counts:
        with tempfile.TemporaryDirectory(prefix="bench-e2e-sweep-") as tmp:
            t0 = time.perf_counter()
            res = run_sweep(doc, out=Path(tmp) / "out", workers=w, progress=False)
            wall = time.perf_counter() - t0
        rate = 60.0 * len(res.cases) / wall
        base = base or rate
        # diagnostic pass: the same cases through a plain spawn pool, per-case wall and CPU
        payloads = [{"case_id": c.case_id, "scenario": c.scenario, "metrics": ["e2_rms"], "record": False}
                    for c in case_list]
        with cf.ProcessPoolExecutor(w, mp_context=multiprocessing.get_context("spawn")) as ex:
            diag = list(ex.map(_timed_case, payloads))
        first, later = {}, []
        for d in diag:
            if d["pid"] not in first:
                first[d["pid"]] = d
            else:
                later.append(d)
        fw = np.median([d["wall"] for d in first.values()])
        lw = np.median([d["wall"] for d in later]) if later else float("nan")
        lc = np.median([d["cpu"] for d in later]) if later else float("nan")
        out(f"| {w} | {wall:.2f} | {rate:.0f} | {rate / base:.2f}x | {fw:.2f} s | {lw:.3f} s / {lc:.3f} s |")
    out("")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="5 s scenario, 6 cases x 1 s, 1 repetition")
    ap.add_argument("--reps", type=int, default=None, help="repetitions of the run (default 3; quick 1)")
    ap.add_argument("--cases", type=int, default=None, help="sweep cases (default 8; quick 6)")
    ap.add_argument("--no-sweep", action="store_true", help="skip the sweep table")
    ap.add_argument("--write", action="store_true", help="append the tables to benchmarks/RESULTS.md")
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
    overrides = ["duration=5", "transient=1"] if args.quick else []
    run_table("scenarios/paper.toml", overrides, args.reps or (1 if args.quick else 3), out)
    if not args.no_sweep:
        sweep_table(args.cases or (6 if args.quick else 8), 1.0 if args.quick else 2.0,
                    sorted({1, 2, os.cpu_count() or 1}), out)
    load = os.getloadavg()
    out(f"Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}.\n")
    if args.write:
        with open(ROOT / "benchmarks" / "RESULTS.md", "a", encoding="utf-8") as f:
            f.write("\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
