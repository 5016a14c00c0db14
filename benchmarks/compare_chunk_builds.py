"""Loop CPU time of several builds of the compiled MuJoCo loop in ONE process (a benchmark tool; it asserts
nothing).

    .venv/bin/python benchmarks/compare_chunk_builds.py AOT_DIR_A AOT_DIR_B [...] [--reps 20]

Each AOT_DIR is a kernel-cache folder `aot-<digest>-<recipe>` (`teleop cache` lists them) holding a build of
`mujoco_chunk` (harness.loop.aot): build one per code version by running that version once.  The builds
must share `mujoco_chunk`'s argument list with this checkout, which sets up every run.  They are loaded side
by side and run in turn (order reversed every other round) on the paper scenario; CPU time per run (model
build excluded) and its ratio to the first build, run by run: machine drift hits every build alike, which
process pairs on a noisy machine cannot achieve.  A raw `mj_step` replay of the same steps each round gives
/raw.  The loop runs serially (`overlap=False`): the physics thread's spin-waits would count as CPU time, and
whether it is kept would differ from run to run.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_loop import logged_run, raw_replay_s  # noqa: E402  (this folder: the script's own)

from harness.config.load import load_scenario  # noqa: E402
from harness.loop import mujoco_loop as ML  # noqa: E402
from harness.loop.aot import A as REAL_A  # noqa: E402


class _Select:
    """Stands for `harness.loop.aot.A` in the MuJoCo loop: mujoco_chunk is the selected build."""

    fn = None

    def __getattr__(self, name):
        return self.fn if name == "mujoco_chunk" else getattr(REAL_A, name)


def _load(folder: Path):
    paths = sorted(folder.glob("octarm_mujoco_chunk_*.so"))
    if not paths:
        raise SystemExit(f"{folder}: no octarm_mujoco_chunk_*.so (run that code version once to build it)")
    name = paths[0].name.split(".")[0]
    spec = importlib.util.spec_from_file_location(name, paths[0])
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.mujoco_chunk


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds (default: the scenario's)")
    ap.add_argument("--segments", type=int, default=None,
                    help="the CC chain with this many segments per section (default: the paper's plant)")
    args = ap.parse_args(argv)
    fns = {f.name: _load(f) for f in args.folders}
    sel = _Select()
    ML.A = sel
    cc = [] if args.segments is None else ["plant.enforce_cc=true", f"plant.segments={args.segments}"]
    scn = load_scenario(ROOT / "scenarios" / "paper.toml", cc)
    if args.duration is not None:  # after validation: shorter than the transient is fine here
        scn = dataclasses.replace(scn, duration=args.duration)
    sel.fn = next(iter(fns.values()))
    _, log = logged_run(scn)  # the first build's commands, replayed raw each round

    def raw() -> float:
        return raw_replay_s(scn, log, clock=time.process_time)

    raw()  # loads the replay kernel (numba's cache) outside the timings
    names = list(fns)
    for k in names:  # warm every build once
        sel.fn = fns[k]
        ML.simulate_mujoco(scn, overlap=False)
    cpu = {k: [] for k in names}
    raws = []
    for rep in range(args.reps):
        for k in names if rep % 2 == 0 else names[::-1]:
            sel.fn = fns[k]
            c = time.process_time()
            tr = ML.simulate_mujoco(scn, overlap=False)
            cpu[k].append(time.process_time() - c - tr.meta["build_time"])
        raws.append(raw())
    first = np.array(cpu[names[0]])
    for k in names:
        v = np.array(cpu[k])
        r = v / first
        print(f"{k}: CPU {np.median(v):.3f} s median, vs {names[0]} {np.median(r):.3f} "
              f"[{r.min():.3f}, {r.max():.3f}], / raw {np.median(v) / np.median(raws):.3f}; "
              f"best of {len(v)}: {v.min():.3f} s, / raw's best {v.min() / min(raws):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
