"""Per-step cost of a controller through the Python interface against the compiled paper loop, on the
same plant (MuJoCo, paper scenario, N = 8), short runs.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_controller.py            # 2 s runs, 3 reps
    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_controller.py --duration 0.5 --reps 1

Rows (each the best of --reps interleaved repetitions of `harness.loop.simulate`, per control step =
traj.meta["wall_time"] / steps, i.e. the control loop without the model build and recording geometry):
  paper (compiled)            the fused compiled loop (controller.name = "paper"), no Python per step
  paper_interface             the same law through the interface: Python loop, compiled law per step
  paper_no_null / dls_ik      built-in numpy baselines (NominalModels with compiled model kernels)
  JacobianTransposePD         examples/controllers/jacobian_transpose.py (torque plant)
Torque rows run on the CC chain (plant.enforce_cc = true: the free chain diverges in torque mode and the
Jacobian-transpose example requires it), servo rows on the default plant.  The "overhead" column is
(per-step - compiled per-step) on the same actuation.  A benchmark: it asserts only that each run
finishes (status ok); the numbers depend on the machine (2 shared cores here).
"""

from __future__ import annotations

import argparse
import time

from harness.api import load_scenario
from harness.loop import simulate

CASES = (
    ("paper (compiled)", "paper", "servo"),
    ("paper_interface", "paper_interface", "servo"),
    ("paper_no_null", "paper_no_null", "servo"),
    ("dls_ik", "dls_ik", "servo"),
    ("paper (compiled)", "paper", "torque"),
    ("paper_interface", "paper_interface", "torque"),
    ("JacobianTransposePD", "examples/controllers/jacobian_transpose.py:JacobianTransposePD", "torque"),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    def plant(act: str) -> list[str]:
        return [f'plant.actuation="{act}"'] + (["plant.enforce_cc=true"] if act == "torque" else [])

    scns = [load_scenario(None, [f"duration={args.duration}", *plant(act), f'controller.name="{name}"'])
            for _, name, act in CASES]
    for s in scns[:1] + scns[4:5]:  # warm-up: kernel load from numba's cache
        simulate(load_scenario(None, ["duration=0.01", *plant(s.plant.actuation)]))
    best = [float("inf")] * len(CASES)
    for _ in range(args.reps):
        for i, s in enumerate(scns):
            t0 = time.perf_counter()
            tr = simulate(s)
            assert tr.status == "ok", (CASES[i], tr.message)
            best[i] = min(best[i], tr.meta["wall_time"] / len(tr))
            _ = time.perf_counter() - t0
    base = {act: best[i] for i, (lab, _, act) in enumerate(CASES) if lab == "paper (compiled)"}
    print(f"duration {args.duration} s ({scns[0].n_steps} control steps), best of {args.reps}\n")
    print("| controller | actuation | us / control step | overhead vs compiled (us) | x compiled |")
    print("|---|---|---:|---:|---:|")
    for (lab, _, act), b in zip(CASES, best, strict=True):
        print(f"| {lab} | {act} | {b * 1e6:.0f} | {(b - base[act]) * 1e6:.0f} | {b / base[act]:.1f} |")


if __name__ == "__main__":
    main()
