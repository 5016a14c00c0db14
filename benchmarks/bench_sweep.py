"""Sweep throughput: cases per minute with 1 worker process vs all cores (a benchmark, not a test).

    .venv/bin/python benchmarks/bench_sweep.py                      # 8 cases x 2 s, MuJoCo plant
    .venv/bin/python benchmarks/bench_sweep.py --cases 16,32 --reps 5 --write   # the issue's measure
    .venv/bin/python benchmarks/bench_sweep.py --plant analytic --duration 5 --cases 16
    .venv/bin/python benchmarks/bench_sweep.py --cases 64 --expand   # only: expanding + validating the cases

Each configuration runs the same small mass-mismatch study (plant slave masses scaled 0.8..1.2)
into a fresh temporary folder through `harness.studies.sweep.run_sweep` in this process, so the wall time
includes starting the worker processes, their first cases, results.jsonl and the summary (csv and plot).
It does not include the imports of a fresh `teleop sweep` process: `benchmarks/bench_core.py` measures
those.  One case is run in this process first, and the summary plot's modules are imported, so that
every configuration starts from the same warm process (the numba cache and the loop's modules loaded,
inherited by forked workers).  The configurations run in turn, --reps times, the order reversed every
other repetition (the machine is noisy); the speedup is the median of the per-repetition ratios.  The
line above the table says how the workers start (fork or spawn, `harness.studies.executor.start_method`).
--write replaces benchmarks/results/bench_sweep.md.
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.studies.executor import start_method  # noqa: E402
from harness.studies.sweep import expand_cases, load_study, run_case, run_sweep  # noqa: E402

SUMMARY_IMPORTS = ("matplotlib.figure",)  # the summary plots' modules


def make_study(cases: int, duration: float, plant: str) -> dict:
    scales = [round(0.8 + 0.4 * i / max(1, cases - 1), 6) for i in range(cases)]
    return {
        "study": {"name": "bench", "set": [f"duration={duration}", "transient=0.0", f"plant.kind='{plant}'"],
                  "metrics": ["e2_rms", "beta_min", "wall_time"]},
        "factor": [{"name": "slave_mass", "param": "plant.slave.masses", "scale": scales}],
    }


def sweep_table(n: int, args, counts: list[int]) -> list[str]:
    """The table of one study of n cases: every worker count in turn, args.reps times."""
    doc = make_study(n, args.duration, args.plant)
    lines = [f"{n} cases x {args.duration:g} s simulated, plant = {args.plant}, {args.reps} repetitions in "
             f"turn, workers start by {start_method()}", ""]
    walls: dict[int, list[float]] = {w: [] for w in counts}
    per_case: dict[int, list[float]] = {w: [] for w in counts}
    statuses: dict[int, set[str]] = {w: set() for w in counts}
    for rep in range(args.reps):
        for w in counts if rep % 2 == 0 else counts[::-1]:
            if start_method() != "fork" and sys.platform.startswith("linux"):
                lines.append(f"note: workers spawn (threads alive: {threading.enumerate()})")
            with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
                t0 = time.perf_counter()
                res = run_sweep(doc, out=Path(tmp) / "out", workers=w, progress=False)
                walls[w].append(time.perf_counter() - t0)
            per_case[w].append(sum(r["wall_time"] for r in res.rows.values()) / max(1, len(res.rows)))
            statuses[w].add(", ".join(f"{k} {s}" for s, k in sorted(res.counts().items())))
    header = (f"{'workers':>7} {'wall s, median [min, max]':>26} {'cases/min':>10} "
              f"{'speedup [min, max]':>20} {'s/case (worker)':>16}  statuses")
    lines += [header, "-" * len(header)]
    w0 = counts[0]
    for w in counts:
        v = walls[w]
        ratio = sorted(a / b for a, b in zip(walls[w0], v, strict=True))
        wall = statistics.median(v)
        lines.append(f"{w:>7} {wall:>8.2f} [{min(v):.2f}, {max(v):.2f}]{'':>8} {60.0 * n / wall:>10.1f} "
                     f"{statistics.median(ratio):>6.2f} [{ratio[0]:.2f}, {ratio[-1]:.2f}]{'':>2} "
                     f"{statistics.median(per_case[w]):>16.3f}  {' / '.join(sorted(statuses[w]))}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="8",
                    help="cases per study; comma-separated: several studies (default 8)")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds per case (default 2)")
    ap.add_argument("--plant", choices=("mujoco", "analytic"), default="mujoco",
                    help="plant (default mujoco)")
    ap.add_argument("--expand", action="store_true",
                    help="only time expanding and validating the cases (serial in the sweep's process before "
                         "any case runs): median of 7, ms per case")
    ap.add_argument("--reps", type=int, default=3, help="repetitions of each configuration (default 3)")
    ap.add_argument("--workers", default=None,
                    help="comma-separated worker counts (default: 1 and os.cpu_count())")
    ap.add_argument("--write", action="store_true", help="replace benchmarks/results/bench_sweep.md")
    args = ap.parse_args(argv)
    n_cases = [int(n) for n in args.cases.split(",")]
    ncpu = os.cpu_count() or 1
    counts = [int(w) for w in args.workers.split(",")] if args.workers else sorted({1, ncpu})
    doc = make_study(n_cases[0], args.duration, args.plant)
    if args.expand:
        from harness.studies.cases import load_base

        study = load_study(doc)
        base = load_base(study)
        times = []
        for _ in range(8):  # the first is a warm-up
            t0 = time.perf_counter()
            expand_cases(study, base)
            times.append(time.perf_counter() - t0)
        times = sorted(times[1:])
        per = [t / n_cases[0] * 1e3 for t in times]
        print(f"expanding + validating {n_cases[0]} cases: {per[len(per) // 2]:.2f} ms per case "
              f"(median of {len(per)}; min {per[0]:.2f})")
        return 0

    case = expand_cases(load_study(doc))[0]
    t0 = time.perf_counter()
    warm = run_case({"case_id": case.case_id, "scenario": case.scenario, "metrics": ["wall_time"],
                     "record": False})
    print(f"warm-up case in this process: {time.perf_counter() - t0:.2f} s, status {warm['status']} "
          f"{warm['message']}".rstrip())
    if warm["status"] == "error":
        print(warm["traceback"], file=sys.stderr)
        return 1

    for name in SUMMARY_IMPORTS:  # the summary plot's modules: no configuration pays their import
        importlib.import_module(name)

    lines = [f"`bench_sweep.py {' '.join(sys.argv[1:] if argv is None else argv)}`, "
             f"load average "
             f"{os.getloadavg()[0]:.2f}, {platform.processor() or platform.machine()}, "
             f"os.cpu_count() = {ncpu}", ""]
    for n in n_cases:
        lines += sweep_table(n, args, counts) + [""]
    print("\n".join(lines))
    if args.write:
        from results import write_result

        write_result(__file__, "## Sweep throughput in one process: `bench_sweep.py`\n\n```\n"
                     + "\n".join(lines).rstrip() + "\n```\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
