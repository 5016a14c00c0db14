"""The MuJoCo loop with and without its physics thread, against raw mj_step (issue: speed; a benchmark, it
asserts nothing).

    .venv/bin/python benchmarks/bench_threads.py            # --reps 7, 20-s paper run + 2-s runs
    .venv/bin/python benchmarks/bench_threads.py --quick    # 2-s runs only

`simulate_mujoco(overlap=True)` steps MuJoCo in a second thread in its two phases: mj_step1 (positions,
velocities) of each state runs while the loop's thread computes the control step from that state; the loop
then asks for mj_step2 (`harness.loop.native.physics_server`).  Same numbers (tests/test_overlap.py).
Per plant, repeated --reps times in alternating order, in this process on every CPU it may use (not pinned):
  raw       the compiled replay of the run's logged [ctrl, qfrc_applied] through the C mj_step (one thread)
  serial    the loop, one thread (overlap=False)
  threaded  the loop with the physics thread from the first step (overlap=True); its CPU time (both threads)
  default   the loop as it runs by default (overlap=None: `overlap_plan`; with 2 CPUs, serial for three
            calls of 100 steps, then the physics thread if its first call is not slower)
and, once per plant, MuJoCo's two phases (mj_step1, mj_step2) timed from Python on the same commands.
Ratios are medians of the per-repetition ratios (each repetition measures all four back to back).
Replaces benchmarks/results/bench_threads.md unless --no-write.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_loop import _machine, logged_run, raw_replay_s  # noqa: E402  (this folder: the script's own)

from harness.config.scenario import PlantConfig, Scenario  # noqa: E402
from harness.loop.mujoco_loop import make_plant, simulate_mujoco  # noqa: E402


def phase_split_us(scn: Scenario, log: np.ndarray, passes: int = 3) -> tuple[float, float]:
    """MuJoCo's two phases per physics step, us (median of `passes` replays of the logged commands, each
    call timed from Python: about 0.3-0.5 us of call overhead included in each): (mj_step1, mj_step2)."""
    s1, s2 = [], []
    for _ in range(passes):
        m, d, _ = make_plant(scn)
        nu, pc = m.nu, time.perf_counter
        t1 = t2 = 0.0
        for row in log:
            d.ctrl[:] = row[:nu]
            d.qfrc_applied[:] = row[nu:]
            a = pc()
            mujoco.mj_step1(m, d)
            b = pc()
            mujoco.mj_step2(m, d)
            t1 += b - a
            t2 += pc() - b
        s1.append(t1 / len(log) * 1e6)
        s2.append(t2 / len(log) * 1e6)
    return float(np.median(s1)), float(np.median(s2))


def median_ci(v: np.ndarray, level: float = 0.95, resamples: int = 2000) -> tuple[float, float]:
    """Bootstrap confidence interval of the median of `v` (percentile method; fixed seed: the same
    repetitions give the same interval)."""
    rng = np.random.default_rng(0)
    meds = np.median(rng.choice(v, size=(resamples, len(v)), replace=True), axis=1)
    return float(np.quantile(meds, (1 - level) / 2)), float(np.quantile(meds, (1 + level) / 2))


def measure(scn: Scenario, reps: int) -> dict:
    """Seconds per repetition: raw, serial, threaded, default (wall), serial_cpu, threaded_cpu, default_cpu
    (process CPU time); default_threaded: the share of the default run's steps the physics thread stepped;
    step1_us, step2_us: `phase_split_us`."""
    tr, log = logged_run(scn)
    keys = ("raw", "serial", "threaded", "default", "serial_cpu", "threaded_cpu", "default_cpu",
            "default_threaded")
    out = {"steps": len(tr), "status": tr.status, **{k: [] for k in keys}}
    out["step1_us"], out["step2_us"] = phase_split_us(scn, log)
    raw_replay_s(scn, log)  # warm: the first replay of the process loads numba and its cached kernel (~1 s)
    modes = {"serial": False, "threaded": True, "default": None}
    for overlap in modes.values():
        simulate_mujoco(scn, overlap=overlap)
    for rep in range(reps):
        out["raw"].append(raw_replay_s(scn, log))
        for key in (list(modes) if rep % 2 == 0 else list(modes)[::-1]):
            c = time.process_time()
            tr = simulate_mujoco(scn, overlap=modes[key])
            cpu = time.process_time() - c
            out[key].append(tr.meta["wall_time"])
            out[key + "_cpu"].append(cpu)
            if key == "default":
                out["default_threaded"].append(tr.meta["overlap_steps"] / max(1, len(tr)))
    return {k: (np.array(v) if isinstance(v, list) else v) for k, v in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--quick", action="store_true", help="2-s runs only")
    ap.add_argument("--no-write", action="store_true",
                    help="do not write benchmarks/results/bench_threads.md")
    args = ap.parse_args(argv)
    cpus = len(os.sched_getaffinity(0))
    base = Scenario()
    plants = []
    if not args.quick:
        plants.append(("paper run, 20 s: N = 8, servo, free chain (default plant)", base))
    short = dataclasses.replace(base, duration=2.0)
    def cc(**kw):
        return dataclasses.replace(short, plant=PlantConfig(enforce_cc=True, **kw))

    plants += [("2 s: N = 8, servo, free chain (default plant)", short),
               ("2 s: N = 8, torque, CC chain", cc(actuation="torque")),
               ("2 s: N = 4, servo, CC chain", cc(segments=4)),
               ("2 s: N = 16, servo, CC chain", cc(segments=16))]
    now = datetime.datetime.now(datetime.UTC)
    lines = [f"# The MuJoCo loop with its physics thread ({now:%Y-%m-%d %H:%M} UTC, "
             f"`benchmarks/bench_threads.py --reps {args.reps}{' --quick' if args.quick else ''}`)\n",
             f"Machine: {_machine()}; {cpus} CPUs for this process.  us per control step, median of "
             f"{args.reps} repetitions (raw, serial, threaded and default back to back in each); ratios: "
             "median of the per-repetition ratios (its 95 % bootstrap confidence interval) [min, max].\n",
             "| plant | raw mj_step | serial loop | threaded loop | serial / raw | **threaded / raw** | "
             "threaded / serial | CPU threaded / serial | **default / raw** | default: steps threaded | "
             "mj_step1 + mj_step2 | serial - raw |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    best = []  # the second table: best / best
    for label, scn in plants:
        r = measure(scn, args.reps)
        best.append((label, *(float(r[k].min() / r["raw"].min()) for k in ("serial", "threaded", "default"))))

        def us(key, r=r):
            return float(np.median(r[key])) / r["steps"] * 1e6

        def ratio(a, b, r=r):
            v = r[a] / r[b]
            lo, hi = median_ci(v)
            return f"{np.median(v):.2f}x ({lo:.2f}-{hi:.2f}) [{v.min():.2f}, {v.max():.2f}]"

        note = "" if r["status"] == "ok" else f" ({r['status']})"
        line = (f"| {label}{note} | {us('raw'):.1f} us | {us('serial'):.1f} us | {us('threaded'):.1f} us "
                f"| {ratio('serial', 'raw')} | **{ratio('threaded', 'raw')}** | "
                f"{ratio('threaded', 'serial')} | {ratio('threaded_cpu', 'serial_cpu')} | "
                f"**{ratio('default', 'raw')}** | {np.median(r['default_threaded']):.0%} "
                f"[{r['default_threaded'].min():.0%}, {r['default_threaded'].max():.0%}] | "
                f"{r['step1_us']:.1f} + {r['step2_us']:.1f} us | {us('serial') - us('raw'):.1f} us |")
        print(line, flush=True)
        lines.append(line)
    lines.append("\nCPU: the process's CPU time over the whole `simulate_mujoco` call (model build and "
                 "geometry included), both threads.  Each thread spin-waits while the other works, so the "
                 "threaded loop costs more CPU for less wall time: by default it is tried only where a core "
                 "is free for it and kept only if its first call is not slower "
                 "(`harness.loop.mujoco_loop.overlap_plan`), never in sweeps.  Default: steps threaded = the "
                 "share of the run's control steps the physics thread stepped, median [min, max].  "
                 "mj_step1 + mj_step2: MuJoCo's two phases per step, each call timed from Python (about "
                 "0.3-0.5 us of call overhead in each).  Serial - raw: what the loop's thread adds per step "
                 "(controller, sensing, commands, records).  With the physics thread a step takes at least "
                 "mj_step2 + max(mj_step1, serial - raw) plus the two threads' hand-overs.")
    lines += [f"\nBest of {args.reps} (each column's fastest repetition over raw's fastest, the estimator of "
              "`bench_loop.py`: on this noisy machine a slow minute only ever adds time):\n",
              "| plant | serial / raw | threaded / raw | default / raw |", "|---|---|---|---|"]
    lines += [f"| {label} | {a:.2f}x | {b:.2f}x | {c:.2f}x |" for label, a, b, c in best]
    print("\n".join(lines[-len(best) - 3:]), flush=True)
    if not args.no_write:
        from results import write_result

        write_result(__file__, "\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
