"""The harness' speed goals in one run: ratios with their spread over alternating repetitions.

    .venv/bin/python benchmarks/bench_core.py              # --reps 10
    .venv/bin/python benchmarks/bench_core.py --reps 3 --cases 16    # a quick look

Run from the checkout's root with a warm kernel cache (one `teleop run` first).  Each measure alternates
its two sides repetition by repetition (A B A B ...), so that a drift of the machine's speed hits both,
and reports the median of the per-pair ratios with its min and max.  This is a benchmark: it asserts
nothing.

  loop / raw        the compiled MuJoCo loop of the paper scenario (20 s, default plant; its loop time,
                    `traj.meta["wall_time"]`) against raw MuJoCo for the same physics steps: the loop
                    logs [ctrl, qfrc_applied] before every mj_step and a compiled loop replays exactly
                    those through MuJoCo's C mj_step, nothing else.  Goal: <= 1.25.
  binding / loop    the same run through the Python-stepped loop (MuJoCo's Python binding `mj_step`, the
                    paper's law in one compiled call per control step) against the compiled loop (C
                    `mj_step` called from compiled code): what the compiled loop buys.
  run / bound       `teleop run` of the paper scenario with every output, a fresh process, wall time,
                    against 1.5 x raw + 1.5 s (raw: the replay above, median).  Goal: <= 1.
  sweep 1 / 2       `teleop sweep` of a CASES-case study (2-s MuJoCo cases) on 1 worker against
                    2 workers, fresh processes, wall time (the speed-up of the second worker).  Goal: >= 1.7.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def spread(ratios: list[float]) -> str:
    r = np.asarray(ratios)
    return f"{np.median(r):.3f} [{r.min():.3f}, {r.max():.3f}] (n = {len(r)})"


def loop_and_raw(reps: int) -> tuple[list[float], list[float], list[float], list[float]]:
    """(loop seconds, raw seconds, Python-stepped seconds, loop seconds paired with them), alternating."""
    import mujoco

    from harness.config.scenario import Scenario
    from harness.loop import simulate
    from harness.loop.common import compile_model
    from harness.loop.fast import K
    from harness.loop.mujoco_loop import make_plant, simulate_mujoco
    from harness.loop.native import MJ_FUNCS
    from harness.loop.stepped_loop import simulate_stepped
    from harness.loop.stepped_plants import stepped_plant
    from harness.plant import build_plant

    scn = Scenario()
    model = compile_model(scn)
    plant = build_plant(scn)
    m, d, _ = make_plant(scn, plant, model.s0)
    log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
    simulate_mujoco(scn, cmd_log=log, plant=plant, model=model)  # warm: kernels loaded
    qpos0, qvel0 = d.qpos.copy(), d.qvel.copy()

    def raw() -> float:
        d.qpos[:], d.qvel[:] = qpos0, qvel0
        d.time = 0.0
        d.qacc_warmstart[:] = 0.0
        mujoco.mj_forward(m, d)
        t0 = time.perf_counter()
        K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
        return time.perf_counter() - t0

    raw()
    loops, raws, binding, loops_b = [], [], [], []
    for _ in range(reps):
        loops.append(simulate(scn, plant=plant).meta["wall_time"])
        raws.append(raw())
    for _ in range(reps):
        loops_b.append(simulate(scn, plant=plant).meta["wall_time"])
        binding.append(simulate_stepped(scn, stepped_plant(scn, model, plant), model=model).meta["wall_time"])
    return loops, raws, binding, loops_b


def _wall(cmd: list[str], cwd: Path) -> float:
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if res.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(cmd)} exited {res.returncode}: {res.stderr[-500:]}")
    return wall


STUDY = """
[study]
name = "bench_core"
description = "speed benchmark: {cases} cases of 2 s, MuJoCo plant"
set = ["duration=2.0", "transient=0.5"]
metrics = ["e2_rms"]

[[factor]]
name = "mass"
param = "plant.slave.masses"
scale = {scales}
"""


def run_and_sweeps(reps: int, cases: int, tmp: Path) -> tuple[list[float], list, list]:
    py = sys.executable
    run = [py, "-m", "harness.cli", "run", "--out", str(tmp / "run"), "--no-progress"]
    _wall(run, ROOT)  # warm the file cache
    runs = [_wall(run, ROOT) for _ in range(reps)]
    study = tmp / "study.toml"
    scales = [round(0.6 + 0.8 * i / max(1, cases - 1), 6) for i in range(cases)]
    study.write_text(STUDY.format(cases=cases, scales=scales))
    one, two = [], []
    for _ in range(reps):
        for workers, out in ((1, one), (2, two)):
            folder = tmp / f"sweep{workers}"
            subprocess.run(["rm", "-rf", str(folder)], check=True)
            out.append(_wall([py, "-m", "harness.cli", "sweep", str(study), "--workers", str(workers),
                              "--out", str(folder), "--no-progress"], ROOT))
    return runs, one, two


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=10, help="repetitions of each pair (default 10)")
    ap.add_argument("--cases", type=int, default=64, help="cases of the sweep study (default 64)")
    ap.add_argument("--no-write", action="store_true", help="print only (default: replace the results file)")
    args = ap.parse_args()
    lines: list[str] = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    say(f"# bench_core: {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.2f}, --reps {args.reps} --cases {args.cases}")
    loops, raws, binding, loops_b = loop_and_raw(args.reps)
    raw_med = float(np.median(raws))
    say(f"raw mj_step, paper run (20 s): {raw_med:.3f} s median; compiled loop {np.median(loops):.3f} s; "
        f"Python-stepped loop {np.median(binding):.3f} s")
    say(f"loop / raw          {spread([a / b for a, b in zip(loops, raws, strict=True)])}   goal <= 1.25")
    pays = spread([a / b for a, b in zip(binding, loops_b, strict=True)])
    say(f"binding / loop      {pays}   (> 1: the compiled loop pays)")
    with tempfile.TemporaryDirectory(prefix="bench_core-") as tmp:
        runs, one, two = run_and_sweeps(args.reps, args.cases, Path(tmp))
    bound = 1.5 * raw_med + 1.5
    say(f"teleop run: {np.median(runs):.2f} s median [{min(runs):.2f}, {max(runs):.2f}]; "
        f"bound 1.5 x raw + 1.5 s = {bound:.2f} s")
    say(f"run / bound         {spread([r / bound for r in runs])}   goal <= 1")
    say(f"sweep of {args.cases}: 1 worker {np.median(one):.1f} s, 2 workers {np.median(two):.1f} s")
    say(f"sweep 1 / 2         {spread([a / b for a, b in zip(one, two, strict=True)])}   goal >= 1.7")
    if not args.no_write:
        from results import write_result

        write_result(__file__, lines[0] + "\n\n```text\n" + "\n".join(lines[1:]) + "\n```\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
