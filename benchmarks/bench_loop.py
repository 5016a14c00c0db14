"""Per-step cost of the harness against raw MuJoCo, in one run on one machine (issue: speed).

    .venv/bin/python benchmarks/bench_loop.py            # default: paper scenario pieces, N in 4..32
    .venv/bin/python benchmarks/bench_loop.py --quick    # fewer steps

Measures (single core, numba kernels warmed up first):
  raw      mj_step of the plant model alone (default N), stepped from compiled code via ctypes (the
           limit) and from a Python loop, with the chain servos holding a fixed reference
  harness  the full control loop per control step (sensing, noise, both laws with the null-space
           terms, actuation, record row) = simulate_mujoco's loop time / steps
  +rrd     the same run plus kinematics replay, Rerun recording and nothing else
  analytic the closed loop on the analytic plant (RK4, 1 step per control step)
  parts    the controller's pieces called one by one (compiled)
  N        raw and harness per step for N in 4, 8, 16, 32, CC constraints on and off
This is a benchmark, not a test: it prints numbers and asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import mujoco
import numba
import numpy as np

from controllers import slave
from controllers.params import Gains, SlaveParams, SubtaskSpec
from controllers.subtasks import pack_subtask
from harness.config import PlantConfig, Scenario
from harness.fast import K
from harness.loop_kernels import MJ_STEP
from harness.mujoco_sim import make_plant
from harness.sim import simulate


@numba.njit
def _raw_loop(mptr, dptr, n):  # pragma: no cover - benchmark helper
    for _ in range(n):
        MJ_STEP(mptr, dptr)


def raw_step_us(scn: Scenario, steps: int) -> tuple[float, float]:
    """(compiled-loop us/step, python-loop us/step) for mj_step of the plant, servos holding q2(0)."""
    m, d, cmap = make_plant(scn)
    q2, _ = cmap.sense(d)
    if scn.plant.actuation == "servo":
        d.ctrl[cmap.chain_actuator_ids] = cmap.joints_from_q2(q2)
    d.ctrl[cmap.master_actuator_ids] = 0.0
    mujoco.mj_forward(m, d)
    state = mujoco.MjData(m)
    mujoco.mj_copyData(state, m, d)
    _raw_loop(m._address, d._address, 10)
    mujoco.mj_copyData(d, m, state)
    t = time.perf_counter()
    _raw_loop(m._address, d._address, steps)
    c = (time.perf_counter() - t) / steps * 1e6
    mujoco.mj_copyData(d, m, state)
    t = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d)
    p = (time.perf_counter() - t) / steps * 1e6
    return c, p


def harness_step_us(scn: Scenario) -> tuple[float, object]:
    tr = simulate(scn)
    if tr.status != "ok":
        return float("nan"), tr
    return tr.meta["wall_time"] / len(tr) * 1e6, tr


def parts_us(reps: int = 5000) -> dict[str, float]:
    p = SlaveParams()
    nodes, w = slave.gauss_legendre01(p.n_quad)
    pk = p.packed()
    q = np.array([0.33, 0.35, 0.4, 1.0, -2.0, 3.0])
    dq = np.random.default_rng(0).normal(size=6)
    x, J, H, Hd = np.empty(2), np.empty((2, 6)), np.empty((2, 6, 6)), np.empty((2, 6, 6))
    M, N = np.empty((6, 6)), np.empty(6)
    gk, sp = Gains().packed(), pack_subtask(SubtaskSpec(), p)
    Jd = np.einsum("iab,b->ia", slave.tip_hessian(p, q), dq)
    grad, graddot, parts = np.empty(6), np.empty(6), np.empty(3)
    outs = (np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(11))
    mpk = np.array([0.6, 0.6, 1, 1, 0.03, 0.03, 0, 0, 9.81])
    q1, dq1 = np.array([0.5, 1.1]), np.array([0.1, -0.2])
    T1, minfo = np.zeros(2), np.zeros(10)
    xd = np.array([0.0, 1.0])
    calls = {
        "master law (12)-(13)": lambda: K.master_control_kernel(mpk, gk, q1, dq1, xd, xd, xd, xd, T1, minfo),
        "tip x2, J2, H, dH/dt": lambda: K.tip_kinematics(q, dq, 3, x, J, H, Hd),
        "M2 and N2 (fused)": lambda: K.mass_nle_kernel(pk, q, dq, nodes, w, M, N),
        "sub-task beta, grad, d/dt": lambda: K.subtask_kernel(sp, J, H, Jd, Hd, q, dq, grad, graddot, parts),
        "slave law (17)-(18) total": lambda: K.slave_control_kernel(pk, nodes, w, gk, sp, q, dq, xd, xd, xd,
                                                                      np.zeros(2), *outs),
    }
    out = {}
    for name, f in calls.items():
        f()
        t = time.perf_counter()
        for _ in range(reps):
            f()
        out[name] = (time.perf_counter() - t) / reps * 1e6
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="2 s runs instead of the 20 s paper scenario")
    ap.add_argument("--segments", default="4,8,16,32", help="N values for the scaling table")
    args = ap.parse_args()
    dur = 2.0 if args.quick else 20.0
    base = Scenario(duration=dur)
    # warm up every compiled kernel (numba cache or first compile)
    simulate(dataclasses.replace(base, duration=0.05))
    simulate(dataclasses.replace(base, duration=0.05, plant=PlantConfig(kind="analytic")))

    print(f"# Harness speed (one core; {numba.config.NUMBA_NUM_THREADS} numba threads unused), "
          f"paper scenario {dur:g} s at 1 kHz\n")
    steps = int(dur / base.control_dt)
    rows = []
    for act in ("servo", "torque"):
        scn = dataclasses.replace(base, plant=dataclasses.replace(base.plant, actuation=act))
        rc, rp = raw_step_us(scn, steps)
        hs, tr = harness_step_us(scn)
        with tempfile.TemporaryDirectory() as tmp:
            from harness.record import write_recording

            t = time.perf_counter()
            tr2 = simulate(scn)
            write_recording(tr2, Path(tmp) / "run.rrd")
            full = (time.perf_counter() - t) / steps * 1e6
        rows.append((act, rc, rp, hs, full, tr.status))
    print("| actuation | raw mj_step (compiled loop) | raw mj_step (Python loop) | harness loop | "
          "harness/raw | run + replay + .rrd | real-time factor (harness loop) |")
    print("|---|---|---|---|---|---|---|")
    for act, rc, rp, hs, full, st in rows:
        print(f"| {act} | {rc:.1f} us | {rp:.1f} us | {hs:.1f} us | {hs / rc:.2f}x | {full:.1f} us | "
              f"{1e3 / hs:.1f}x |")
    tr = simulate(dataclasses.replace(base, plant=PlantConfig(kind="analytic")))
    print(f"\nanalytic plant (RK4, controller at 1 kHz): {tr.meta['wall_time'] / len(tr) * 1e6:.1f} us/step, "
          f"{dur / tr.meta['wall_time']:.0f}x real time\n")
    print("| controller part (compiled) | us/call |\n|---|---|")
    for name, v in parts_us().items():
        print(f"| {name} | {v:.2f} |")
    print("\n| N | CC constraints | nv | raw mj_step | harness loop | harness/raw |\n|---|---|---|---|---|---|")
    for n_seg in [int(v) for v in args.segments.split(",")]:
        for cc in (True, False):
            scn = dataclasses.replace(base, duration=min(dur, 2.0),
                                      plant=dataclasses.replace(base.plant, segments=n_seg, enforce_cc=cc))
            m, _, _ = make_plant(scn)
            rc, _ = raw_step_us(scn, 2000)
            hs, tr = harness_step_us(scn)
            note = "" if tr.status == "ok" else f" ({tr.status}: {tr.message[:40]})"
            print(f"| {n_seg} | {'on' if cc else 'off'} | {m.nv} | {rc:.1f} us | {hs:.1f} us{note} | "
                  f"{hs / rc:.2f}x |")


if __name__ == "__main__":
    main()
