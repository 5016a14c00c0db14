"""Sweep throughput: cases per minute with 1 worker process vs all cores (a benchmark, not a test).

    .venv/bin/python benchmarks/bench_sweep.py                      # 8 cases x 2 s, MuJoCo plant
    .venv/bin/python benchmarks/bench_sweep.py --plant analytic --duration 5 --cases 16
    .venv/bin/python benchmarks/bench_sweep.py --cases 64 --expand   # only: expanding + validating the cases

Each configuration runs the same small mass-mismatch study (plant slave masses scaled 0.8..1.2)
into a fresh temporary folder through `harness.studies.sweep.run_sweep`, so the wall time includes starting
the worker processes and their first-call costs (imports, loading the compiled kernels): what a user
waits for.  One case is run in this process first so that the numba on-disk cache is warm for every
configuration.  The table also gives the mean time per case measured inside the workers.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.studies.sweep import expand_cases, load_study, run_case, run_sweep  # noqa: E402


def make_study(cases: int, duration: float, plant: str) -> dict:
    scales = [round(0.8 + 0.4 * i / max(1, cases - 1), 6) for i in range(cases)]
    return {
        "study": {"name": "bench", "set": [f"duration={duration}", "transient=0.0", f"plant.kind='{plant}'"],
                  "metrics": ["e2_rms", "beta_min", "wall_time"]},
        "factor": [{"name": "slave_mass", "param": "plant.slave.masses", "scale": scales}],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=8, help="number of cases (default 8)")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds per case (default 2)")
    ap.add_argument("--plant", choices=("mujoco", "analytic"), default="mujoco",
                    help="plant (default mujoco)")
    ap.add_argument("--expand", action="store_true",
                    help="only time expanding and validating the cases (serial in the sweep's process before "
                         "any case runs): median of 7, ms per case")
    ap.add_argument("--workers", default=None,
                    help="comma-separated worker counts (default: 1 and os.cpu_count())")
    args = ap.parse_args(argv)
    ncpu = os.cpu_count() or 1
    counts = [int(w) for w in args.workers.split(",")] if args.workers else sorted({1, ncpu})
    doc = make_study(args.cases, args.duration, args.plant)
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
        per = [t / args.cases * 1e3 for t in times]
        print(f"expanding + validating {args.cases} cases: {per[len(per) // 2]:.2f} ms per case "
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

    print(f"\n{args.cases} cases x {args.duration:g} s simulated, plant = {args.plant}, "
          f"os.cpu_count() = {ncpu}\n")
    header = (f"{'workers':>7} {'wall s':>8} {'cases/min':>10} {'speedup':>8} {'s/case (worker)':>16}"
              "  statuses")
    print(header)
    print("-" * len(header))
    base = None
    for w in counts:
        with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
            t0 = time.perf_counter()
            res = run_sweep(doc, out=Path(tmp) / "out", workers=w, progress=False)
            wall = time.perf_counter() - t0
        rate = 60.0 * len(res.cases) / wall
        base = base or rate
        per_case = sum(r["wall_time"] for r in res.rows.values()) / max(1, len(res.rows))
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(res.counts().items()))
        print(f"{w:>7} {wall:>8.2f} {rate:>10.1f} {rate / base:>8.2f} {per_case:>16.2f}  {statuses}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
