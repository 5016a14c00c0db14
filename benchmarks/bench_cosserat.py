"""Real-time factor of the Cosserat-rod plant next to the MuJoCo chain, in one run on one machine.

    .venv/bin/python benchmarks/bench_cosserat.py              # 2 s runs, best of 2
    .venv/bin/python benchmarks/bench_cosserat.py --duration 5 --reps 3
    .venv/bin/python benchmarks/bench_cosserat.py --cpu -1     # do not pin to one core
    .venv/bin/python benchmarks/bench_cosserat.py --duration 0.5 --reps 15 --clock cpu --no-write
                                                               # loop / bare on a busy shared machine

--clock cpu times with the process's CPU time (time.process_time, for every timer of the process, the
loop's own wall_time included) instead of wall time: other processes' time slices do not count, so
loop / bare is stable on a shared machine (short runs, many interleaved repetitions, best kept).

The process is pinned to one core (default: the last CPU).  Every timing is the best of --reps
repetitions (the machine is noisy).  Rows, all on the paper scenario (40 dB, servo, seed 0):
  cosserat loop     harness.loop.simulate on plant.kind = "cosserat" at its default resolution
                    (10 elements per section, dt "auto"): the stepped loop's wall time (the plant seen
                    through a wrapper that logs each command and forwards the rest of its interface)
  cosserat bare     the same plant, reset to the same state, replaying the commands the loop sent
                    (plant.command + plant.advance per control step, no sensing, no controller);
                    loop and bare repetitions are interleaved
  cosserat bare+fit bare + plant.true_state (the CC fit) per step
  mujoco default    harness.loop.simulate, plant.kind = "mujoco", N = 8: the default plant (free chain,
                    material damping)
  mujoco CC on      the same with plant.enforce_cc = true
and the stepped loop's overhead: loop / bare (the goal: <= 1.25).
Prints a markdown table and replaces benchmarks/results/bench_cosserat.md with it (unless --no-write).
This is a benchmark, not a test: it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from harness.config.load import load_scenario
from harness.loop import simulate
from harness.plant import build_plant
from harness.plant.initial import initial_state

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_loop import _pin  # noqa: E402 - one CPU-pinning helper for every benchmark

ROOT = Path(__file__).resolve().parents[1]


class _Logging:
    """Wraps a stepped plant and logs every command of a closed-loop run (for the bare replay)."""

    def __init__(self, plant):
        self.plant = plant
        self.log: list[np.ndarray] = []
        for k in ("kind", "actuation", "physics_dt"):
            setattr(self, k, getattr(plant, k))

    def reset(self, s0):
        self.plant.reset(s0)

    def command(self, T1, T2, q, dq, q_sensed):
        self.log.append(np.concatenate([T1, T2, q, dq, q_sensed]))
        self.plant.command(T1, T2, q, dq, q_sensed)

    def __getattr__(self, name):  # everything else is the plant's own (advance, true_state, record, ...)
        return getattr(self.plant, name)


def scenario(duration: float, *extra: str):
    return load_scenario(ROOT / "scenarios" / "paper.toml", [f"duration={duration}", "transient=0", *extra])


def closed_loop(scn, reps: int) -> tuple[float, str]:
    best, status = np.inf, ""
    for _ in range(reps):
        tr = simulate(scn)
        best = min(best, float(tr.meta["wall_time"]))
        status = tr.status if tr.status == "ok" else f"{tr.status}: {tr.message}"
    return best, status


def cosserat_rows(duration: float, reps: int) -> dict:
    """Closed loop, bare stepping and bare + CC fit, interleaved repetitions (best of each), so that
    a change of machine load hits all three alike."""
    scn = scenario(duration, "plant.kind=cosserat")
    plant = _Logging(build_plant(scn))
    s0 = initial_state(scn)
    dt = scn.control_dt
    p = plant.plant
    state = np.zeros(16)

    def bare(cmds: np.ndarray, fit: bool) -> float:
        p.reset(s0)
        t0 = time.perf_counter()
        for c in cmds:
            if fit:
                p.true_state(state)
            p.command(c[0:2], c[2:8], c[8:14], c[14:20], c[20:26])
            p.advance(dt)
        return time.perf_counter() - t0

    best = {"loop": np.inf, "bare": np.inf, "bare_fit": np.inf}
    status, cmds = "", np.zeros((0, 26))
    for _ in range(reps):
        plant.log.clear()
        tr = simulate(scn, plant)
        best["loop"] = min(best["loop"], float(tr.meta["wall_time"]))
        status = tr.status if tr.status == "ok" else f"{tr.status}: {tr.message}"
        cmds = np.array(plant.log)
        if len(cmds) != len(tr):  # the wrapper must see every command, or the comparison is void
            raise RuntimeError(f"logged {len(cmds)} commands for {len(tr)} steps ({status})")
        best["bare"] = min(best["bare"], bare(cmds, False))
        best["bare_fit"] = min(best["bare_fit"], bare(cmds, True))
    return {"scn": scn, "status": status, "steps": len(cmds), "rod_dt": p.physics_dt,
            "elements": p.slave.n, **best}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run (2-5)")
    ap.add_argument("--reps", type=int, default=2, help="repetitions, best kept")
    ap.add_argument("--cpu", type=int, default=-1 if (os.cpu_count() or 1) < 2 else 1,
                    help="index of the CPU to pin to (-1: no pinning)")
    ap.add_argument("--no-write", action="store_true",
                    help="do not write benchmarks/results/bench_cosserat.md")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall time (default) or the process's CPU time (see above)")
    args = ap.parse_args()
    if args.clock == "cpu":  # every timer of this process, the stepped loop's wall_time included
        time.perf_counter = time.process_time
    pin = _pin(args.cpu)
    # warm-up: kernels loaded from numba's cache, plants built once
    simulate(scenario(0.01, "plant.kind=cosserat"))
    simulate(scenario(0.01))
    c = cosserat_rows(args.duration, args.reps)
    T = args.duration
    mj_def, st_def = closed_loop(scenario(T), args.reps)
    mj_on, st_on = closed_loop(scenario(T, "plant.enforce_cc=true"), args.reps)
    n = c["steps"]
    rows = [
        ("Cosserat rod, closed loop (stepped loop)", c["loop"], c["status"]),
        ("Cosserat rod, bare stepping (command + advance)", c["bare"], "-"),
        ("Cosserat rod, bare stepping + CC fit", c["bare_fit"], "-"),
        ("MuJoCo chain N = 8, default (free, material damping), closed loop", mj_def, st_def),
        ("MuJoCo chain N = 8, CC on, closed loop", mj_on, st_on),
    ]
    lines = [
        f"# Cosserat plant speed (`benchmarks/bench_cosserat.py --duration {T:g} --reps {args.reps}"
        f"{' --clock cpu' if args.clock == 'cpu' else ''}`)", "",
        f"{platform.processor() or platform.machine()}, clock: {args.clock}, Python "
        f"{sys.version.split()[0]}, {pin}, os.getloadavg() = {tuple(round(x, 1) for x in os.getloadavg())}.",
        f"Paper scenario, {T:g} s simulated ({n} control steps of {c['scn'].control_dt * 1e3:g} ms), 40 dB, "
        f"servo, seed 0. Rod: {c['elements']} elements per section, dt = {c['rod_dt'] * 1e6:.1f} us "
        f"({round(c['scn'].control_dt / c['rod_dt'])} rod steps per control step). Best of {args.reps}.", "",
        f"| run | {'CPU' if args.clock == 'cpu' else 'wall'} [s] | real-time factor | us / control step "
        "| status |",
        "|---|---:|---:|---:|---|",
    ]
    for name, wall, status in rows:
        lines.append(f"| {name} | {wall:.3f} | {T / wall:.3f} | {wall / n * 1e6:.0f} | {status} |")
    lines += ["", f"Stepped-loop overhead: loop / bare stepping = {c['loop'] / c['bare']:.3f} "
              f"(loop / (bare + CC fit) = {c['loop'] / c['bare_fit']:.3f}); goal <= 1.25.", ""]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        from results import write_result

        write_result(__file__, text)


if __name__ == "__main__":
    main()
