"""The MuJoCo loop or its raw-MuJoCo equivalent alone, for instruction and cache profilers (a benchmark
tool; it asserts nothing).

    .venv/bin/python benchmarks/profile_loop.py log 1.0   # once: the run's [ctrl, qfrc_applied] into --log
    valgrind --tool=callgrind .venv/bin/python benchmarks/profile_loop.py loop 1.0
    valgrind --tool=cachegrind --cache-sim=yes --I1=32768,8,64 --D1=32768,8,64 --LL=524288,8,64 \\
        .venv/bin/python benchmarks/profile_loop.py raw 1.0
    callgrind_annotate --inclusive=yes --tree=calling --threshold=100 --auto=no callgrind.out.<pid>

loop: `simulate_mujoco` of the paper scenario cut to DURATION seconds (the default plant).  raw: the same
physics steps by `mujoco.rollout` (MuJoCo's C++ loop) from the same initial state with the logged commands,
nothing else.  Compare the `mj_*` functions between the two.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness.config.load import load_scenario  # noqa: E402
from harness.loop.mujoco_loop import make_plant, simulate_mujoco  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("log", "loop", "raw"))
    ap.add_argument("duration", type=float, nargs="?", default=1.0, help="simulated seconds (default 1)")
    ap.add_argument("--log", default="/tmp/octarm-cmdlog.npy", help="command log file (default %(default)s)")
    ap.add_argument("--segments", type=int, default=None,
                    help="the CC chain with this many segments per section (default: the paper's plant)")
    args = ap.parse_args(argv)
    cc = [] if args.segments is None else ["plant.enforce_cc=true", f"plant.segments={args.segments}"]
    # the duration after validation: runs shorter than the scenario's transient are fine here
    scn = dataclasses.replace(load_scenario(ROOT / "scenarios" / "paper.toml", cc), duration=args.duration)
    if args.mode == "log":
        m, _, _ = make_plant(scn)
        log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
        tr = simulate_mujoco(scn, cmd_log=log)
        np.save(args.log, log[:len(tr) * scn.substeps])
        print(f"{len(tr)} steps, status {tr.status}: {args.log}")
    elif args.mode == "loop":
        tr = simulate_mujoco(scn)
        print(f"{len(tr)} steps, status {tr.status}")
    else:
        import mujoco
        import mujoco.rollout

        log = np.load(args.log)
        m, d, _ = make_plant(scn)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.zeros(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, state, spec)
        ctrl_spec = int(mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_QFRC_APPLIED)
        out, _ = mujoco.rollout.rollout(m, d, state[None], log[None], control_spec=ctrl_spec)
        print(f"{out.shape[1]} steps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
