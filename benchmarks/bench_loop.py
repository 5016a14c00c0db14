"""Per-step cost of the harness against raw MuJoCo, in one run on one machine.

    .venv/bin/python benchmarks/bench_loop.py            # paper scenario (20 s), N in 4..32 (2 s runs)
    .venv/bin/python benchmarks/bench_loop.py --quick    # 2 s runs
    .venv/bin/python benchmarks/bench_loop.py --cpu -1   # do not pin to one core

The process is pinned to one core (default: the last CPU), so that Rerun's background file-writer
thread and everything else share it: "one core" wall time.  Every timing is the best of --reps
interleaved repetitions (the machine is noisy).  Measures:
  raw      MuJoCo alone for the same physics steps: the harness run logs [ctrl, qfrc_applied] before
           every mj_step (`mujoco_chunk`'s cmd_log); a compiled loop replays exactly those commands
           from the same initial state, calling the C mj_step through ctypes (nothing else)
  harness  the full control loop per control step (sensing, noise, both laws with the null-space
           terms, actuation, elastic correction, record row) = simulate_mujoco's loop time / steps
  + rec    + the recording geometry (compiled mj_kinematics replay, analytic backbone) and the
           Trajectory, i.e. simulate_mujoco's wall time without the model build
  + .rrd   + write_recording (the Rerun file, fully flushed)
  one-time imports, first-call kernel load from numba's on-disk cache (every kernel, the MuJoCo loop
           included, is cached), the compile into an empty cache (skip with --no-cold), model build
  parts    the controller's pieces, each timed in a compiled loop over the recorded states of the
           servo run (no Python call overhead), and the remainder of the loop
  N        raw and harness per control step vs segments per section (CC on; CC off diverges with
           the paper's gains for N >= 4: raw mj_step only, servos holding the initial shape)
Prints markdown tables and replaces benchmarks/results/bench_loop.md with them (unless --no-write).
This is a benchmark, not a test: it asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numba
import numpy as np

from controllers.control import DET_MIN, MASTER_INFO, SLAVE_INFO
from harness.config.scenario import PlantConfig, Scenario
from harness.loop.analytic_loop import simulate_analytic
from harness.loop.common import compile_model, noise_table
from harness.loop.fast import K
from harness.loop.mujoco_loop import (
    LIVE_GEOMETRY_INTEGRATORS,
    Geometry,
    make_plant,
    plant_groups,
    simulate_mujoco,
)
from harness.loop.native import MJ_FUNCS
from harness.loop.trajectory import ROW_WIDTH
from harness.output.record import write_recording
from harness.plant.mujoco_model import MujocoPlant

ROOT = Path(__file__).resolve().parent.parent


# ---------------------------------------------------------------------------------------------
# raw MuJoCo
# ---------------------------------------------------------------------------------------------
def logged_run(scn: Scenario):
    """Harness run with the command log: (trajectory, cmd_log (steps * substeps, nu + nv))."""
    m, _, _ = make_plant(scn)
    log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
    tr = simulate_mujoco(scn, cmd_log=log)
    return tr, log[:len(tr) * scn.substeps]


def raw_replay_s(scn: Scenario, log: np.ndarray, clock=time.perf_counter) -> float:
    """Seconds for the compiled replay of the logged commands (raw mj_step) from the initial state, by
    `clock` (wall time; `time.process_time` for CPU time)."""
    m, d, _ = make_plant(scn)
    t = clock()
    K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
    return clock() - t


def raw_replay_variant_s(scn: Scenario, log: np.ndarray, integrator: str | None = None,
                         solver_defaults: bool = False) -> tuple[float, int]:
    """raw_replay_s of the same logged commands on a variant of the plant model: another integrator
    and/or MuJoCo's default solver flags (warm start and island discovery on, which the scene turns
    off).  Returns (seconds, max Newton iterations of the last step)."""
    m, d, _ = make_plant(scn)
    if integrator is not None:
        m.opt.integrator = INTEGRATOR_ENUM[integrator]
    if solver_defaults:
        m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_WARMSTART | mujoco.mjtDisableBit.mjDSBL_ISLAND)
    t = time.perf_counter()
    K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
    return time.perf_counter() - t, int(d.solver_niter[0])


INTEGRATOR_ENUM = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
                   "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT, "euler": mujoco.mjtIntegrator.mjINT_EULER,
                   "rk4": mujoco.mjtIntegrator.mjINT_RK4}


def _cc(scn: Scenario) -> str:
    return ("CC equality constraints on" if scn.plant.enforce_cc
            else "free chain: CC equality constraints off, material damping (the default plant)")


def settings_table(base: Scenario, reps: int, out) -> None:
    """Solver flags and integrator: raw cost of the same physics steps, and closed-loop stability."""
    scn = dataclasses.replace(base, duration=min(base.duration, 2.0))
    _, log = logged_run(scn)
    variants = [("implicitfast", False, "the plant's setting (scene.xml)"),
                ("implicitfast", True, "MuJoCo's default solver flags (warm start, islands)"),
                ("implicit", False, ""), ("euler", False, ""), ("rk4", False, "")]
    times = {v: [] for v in variants}
    for _ in range(max(reps, 5)):  # interleaved
        for v in variants:
            times[v].append(raw_replay_variant_s(scn, log, v[0], v[1])[0])
    ref = min(times[variants[0]])
    out(f"\nPlant settings (servo, N = {scn.plant.segments}, {_cc(scn)}; raw mj_step replaying the same "
        f"logged commands of a {scn.duration:g} s run, best of {max(reps, 5)} interleaved; 'closed loop' = "
        "the harness run with that integrator):\n")
    out("| integrator | solver flags | raw mj_step | vs plant setting | closed loop | closed loop, servos at "
        f"{STIFF_SERVO_HZ:g} Hz | note |")
    out("|---|---|---|---|---|---|---|")

    def loop_status(integ: str, **plant_kw) -> str:
        plant = dataclasses.replace(scn.plant, integrator=integ, **plant_kw)
        tr = simulate_mujoco(dataclasses.replace(scn, plant=plant))
        return tr.status if tr.status == "ok" else f"{tr.status} at t = {tr.t[-1]:.3f} s"

    for v in variants:
        integ, defaults, note = v
        best = min(times[v])
        loops = ["same physics (tested)"] * 2
        if not defaults:
            loops = [loop_status(integ), loop_status(integ, servo_frequency=STIFF_SERVO_HZ)]
        flags = "warm start + islands" if defaults else "cold start, no islands"
        out(f"| {integ} | {flags} | {best / len(log) * 1e6:.1f} us | {best / ref:.2f}x | {loops[0]} | "
            f"{loops[1]} | {note} |")


STIFF_SERVO_HZ = 80.0  # a stiffer servo than the default 20 Hz (servo gains are a mismatch factor)


def raw_hold_s(scn: Scenario, steps: int) -> float:
    """Seconds for `steps` raw mj_step with the chain servos holding the initial q2 (no controller):
    the only raw baseline where the harness itself diverges (free chain, CC off)."""
    m, d, cmap = make_plant(scn)
    log = np.zeros((steps, m.nu + m.nv))
    if scn.plant.actuation == "servo":
        q2, _ = cmap.sense(d)
        log[:, cmap.chain_actuator_ids] = cmap.joints_from_q2(q2)
    t = time.perf_counter()
    K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
    return time.perf_counter() - t


# ---------------------------------------------------------------------------------------------
# controller parts, timed in compiled loops over recorded states
# ---------------------------------------------------------------------------------------------
def _part_timers() -> dict:
    """The loop's pieces, each the production kernel called as `mujoco_chunk` calls it (plant groups of
    `mujoco_loop.plant_groups`, the law tuple of `kernels.loop_chunk`), in a compiled loop over the
    recorded states."""
    sense, sense_state, desired = K.sense_mujoco, K.sense_state, K.desired
    mlaw, slaw, rec, cmds = K.master_control_kernel, K.slave_control_kernel, K.record_row, K.mujoco_command
    elastic, tipk, massnle = K.chain_elastic_correction, K.tip_kinematics, K.mass_nle_kernel
    sub = K.subtask_kernel

    @numba.njit
    def t_sense(QP, QV, master, chain, S):  # as `mujoco_sense`, with MuJoCo's qpos, qvel of step k
        for k in range(QP.shape[0]):
            sense((QP[k], QV[k]) + master[2:], chain, S[k])

    @numba.njit
    def t_desired(traj, dt, XD):
        for k in range(XD.shape[0]):
            desired(traj, k * dt, XD[k, 0], XD[k, 1], XD[k, 2])

    @numba.njit
    def t_noise(S, noise, row0, scale, SN):  # as `control_step`; row0: the table's row 0 at the start
        noise[0] = row0  # a fresh table (running powers, dq2 filter) per run
        for k in range(S.shape[0]):
            sense_state(S[k], noise, k, scale, SN[k])

    @numba.njit
    def t_master(mpk, gains, SN, XD, F, MI, T1s, D1):  # as `control_laws`
        for k in range(SN.shape[0]):
            D1[k] = mlaw(mpk, gains, SN[k, 0:2], SN[k, 2:4], XD[k, 0], XD[k, 1], XD[k, 2], F[0:2], T1s[k],
                         MI[k])

    @numba.njit
    def t_slave(spk, nodes, weights, gains, spec, SN, MI, F, T2s, U2s, DEN, SI, D2):  # as `control_laws`
        for k in range(SN.shape[0]):
            D2[k] = slaw(spk, nodes, weights, gains, spec, SN[k, 4:10], SN[k, 10:16], MI[k, 0:2], MI[k, 8:10],
                         MI[k, 6:8], F[2:4], T2s[k], U2s[k], DEN[k], SI[k])

    @numba.njit
    def t_tip(SN, order):  # as `slave_control_kernel`
        x = np.empty(2)
        J = np.empty((2, 6))
        H = np.empty((2, 6, 6))
        Hd = np.empty((2, 6, 6))
        for k in range(SN.shape[0]):
            tipk(SN[k, 4:10], SN[k, 10:16], order, x, J, H, Hd)

    @numba.njit
    def t_mass(spk, nodes, weights, SN):  # as `slave_control_kernel`
        M = np.empty((6, 6))
        N = np.empty(6)
        for k in range(SN.shape[0]):
            massnle(spk, SN[k, 4:10], SN[k, 10:16], nodes, weights, M, N)

    @numba.njit
    def tip_terms(SN, TJ, TH, TJd, THd):  # not timed: J2, H, dJ2 = H dq2, dH/dt of each step's state
        x = np.empty(2)
        for k in range(SN.shape[0]):
            tipk(SN[k, 4:10], SN[k, 10:16], 3, x, TJ[k], TH[k], THd[k])
            for i in range(2):
                for a in range(6):
                    acc = 0.0
                    for b in range(6):
                        acc += TH[k, i, a, b] * SN[k, 10 + b]
                    TJd[k, i, a] = acc

    @numba.njit
    def t_sub(spec, SN, TJ, TH, TJd, THd):  # as `slave_control_kernel`, on each step's tip terms
        g = np.empty(6)
        gd = np.empty(6)
        parts = np.empty(3)
        for k in range(SN.shape[0]):
            sub(spec, TJ[k], TH[k], TJd[k], THd[k], SN[k, 4:10], SN[k, 10:16], g, gd, parts)

    @numba.njit
    def t_record(dt, S, SN, XD, model, T1s, T2s, U2s, DEN, MI, SI, info, rows):  # as `control_step`
        for k in range(S.shape[0]):
            law = (T1s[k], T2s[k], U2s[k], DEN[k], MI[k], SI[k], XD[k, 0], XD[k, 1], XD[k, 2], SN[k])
            rec(k * dt, S[k], model, law, rows[k], info[k])

    @numba.njit
    def t_cmds(SN, XD, T1s, T2s, U2s, DEN, MI, SI, groups, ref0, CMD):  # as `loop_chunk`
        ref = groups[6][8]
        ref[:] = ref0  # the servo reference of step 0
        for k in range(SN.shape[0]):
            law = (T1s[k], T2s[k], U2s[k], DEN[k], MI[k], SI[k], XD[k, 0], XD[k, 1], XD[k, 2], SN[k])
            cmds(CMD[k], law, groups)

    @numba.njit
    def t_elastic(QP, chain):  # as `mujoco_advance`, per substep
        c_qadr, eargs, qc, corr = chain[0], chain[5], chain[6], chain[8]
        for k in range(QP.shape[0]):
            for c in range(c_qadr.shape[0]):
                qc[c] = QP[k, c_qadr[c]]
            elastic(qc, *eargs, corr)

    return dict(sense=t_sense, desired=t_desired, noise=t_noise, master=t_master, slave=t_slave, tip=t_tip,
                mass=t_mass, tip_terms=tip_terms, sub=t_sub, record=t_record, cmds=t_cmds, elastic=t_elastic)


def _best(reps: int, f, *args) -> float:
    f(*args)  # compile / warm
    best = np.inf
    for _ in range(reps):
        t = time.perf_counter()
        f(*args)
        best = min(best, time.perf_counter() - t)
    return best


def parts_us(scn: Scenario, log: np.ndarray, reps: int) -> dict[str, float]:
    """us per control step of each piece of the harness loop, on the states of a logged run."""
    plant = MujocoPlant.build(scn)
    m, d, cmap = make_plant(scn, plant)
    n, sub = len(log) // scn.substeps, scn.substeps
    QP, QV = np.zeros((n, m.nq)), np.zeros((n, m.nv))
    for k in range(n):  # states at the start of each control step (replayed)
        QP[k], QV[k] = d.qpos, d.qvel
        K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied,
                          log[k * sub:(k + 1) * sub])
    T = _part_timers()
    a = compile_model(scn)
    geo = Geometry(m, d, cmap, n, live=scn.plant.integrator in LIVE_GEOMETRY_INTEGRATORS)
    groups = plant_groups(scn, m, d, cmap, plant.contact, a, n,
                          (geo.qpos_hist, np.zeros((0, m.nu + m.nv)), geo.inputs, geo.rec))
    master, chain, act = groups[1], groups[2], groups[6]
    noise, scale = noise_table(scn, n)
    S, SN, XD = np.zeros((n, 16)), np.zeros((n, 16)), np.zeros((n, 3, 2))
    MI, SI = np.zeros((n, MASTER_INFO)), np.zeros((n, SLAVE_INFO))
    T1s, T2s, U2s, DEN = np.zeros((n, 2)), np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 6))
    D1, D2 = np.zeros(n), np.zeros(n)
    rows = np.zeros((n, ROW_WIDTH))
    CMD = np.zeros((n, 2 + 2 * cmap.n_chain))
    TJ, TJd = np.zeros((n, 2, 6)), np.zeros((n, 2, 6))
    TH, THd = np.zeros((n, 2, 6, 6)), np.zeros((n, 2, 6, 6))
    r: dict[str, float] = {}
    r["sense (joints -> q2, dq2)"] = _best(reps, T["sense"], QP, QV, master, chain, S)
    r["desired x_d(t)"] = _best(reps, T["desired"], a.traj, scn.control_dt, XD)
    r["noise (AWGN)"] = _best(reps, T["noise"], S, noise, noise[0].copy(), scale, SN)
    r["master law (12)-(13)"] = _best(reps, T["master"], a.mpk_c, a.gains, SN, XD, a.F, MI, T1s, D1)
    r["slave law (17)-(18) + null space"] = _best(reps, T["slave"], a.spk_c, a.nodes, a.weights, a.gains,
                                                  a.spec, SN, MI, a.F, T2s, U2s, DEN, SI, D2)
    r["  of which tip x2, J2, H, dH/dt"] = _best(reps, T["tip"], SN, 3)
    r["  of which M2, N2 (8 GL points/section)"] = _best(reps, T["mass"], a.spk_c, a.nodes, a.weights, SN)
    T["tip_terms"](SN, TJ, TH, TJd, THd)
    r["  of which sub-task beta, grad, rate"] = _best(reps, T["sub"], a.spec, SN, TJ, TH, TJd, THd)
    info = (scale == 0.0) & (D1 != 0.0) & (D2 > DET_MIN)  # the laws ran on the true state with status 0
    r["record row (true state)"] = _best(reps, T["record"], scn.control_dt, S, SN, XD, a, T1s, T2s, U2s, DEN,
                                         MI, SI, info, rows)
    r["commands (servo ref / torque map)"] = _best(reps, T["cmds"], SN, XD, T1s, T2s, U2s, DEN, MI, SI,
                                                   groups, act[8].copy(), CMD)
    r[f"elastic correction (x{sub} substeps)"] = sub * _best(reps, T["elastic"], QP, chain)
    return {k: v / n * 1e6 for k, v in r.items()}


# ---------------------------------------------------------------------------------------------
# harness runs
# ---------------------------------------------------------------------------------------------
def harness_vs_raw(scn: Scenario, reps: int, rrd: bool) -> dict:
    """Seconds per repetition (raw replay and harness interleaved): raw, loop, sim (= loop + recording
    geometry + Trajectory, without the model build), rrd_write, total = sim + rrd_write."""
    tr, log = logged_run(scn)
    keys = ("raw", "loop", "sim", "rrd_write", "total", "build", "geometry")
    out = {"steps": len(tr), "status": tr.status, "message": tr.message, "log": log, **{k: [] for k in keys}}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(reps):
            out["raw"].append(raw_replay_s(scn, log))
            t = time.perf_counter()
            tr = simulate_mujoco(scn)
            sim = time.perf_counter() - t - tr.meta["build_time"]
            out["loop"].append(tr.meta["wall_time"])
            out["geometry"].append(tr.meta["geometry_time"])
            out["build"].append(tr.meta["build_time"])
            out["sim"].append(sim)
            if rrd:
                t = time.perf_counter()
                write_recording(tr, Path(tmp) / f"run{rep}.rrd")
                w = time.perf_counter() - t
                out["rrd_write"].append(w)
                out["total"].append(sim + w)
    for k in keys:
        out[k] = np.array(out[k]) if out[k] else np.full(reps, np.nan)
    return out


def best_us(r: dict, key: str) -> float:
    return float(np.min(r[key])) / r["steps"] * 1e6


def paired_ratio(r: dict, key: str) -> float:
    """Median over repetitions of key / raw measured back to back (robust to slow phases)."""
    return float(np.median(r[key] / r["raw"]))


_COLD = """
import time
t0 = time.perf_counter()
from harness.config.scenario import Scenario
from harness.loop.mujoco_loop import simulate_mujoco
t1 = time.perf_counter()
scn = Scenario(duration=0.01)
tr = simulate_mujoco(scn); t2 = time.perf_counter()
tr = simulate_mujoco(scn); t3 = time.perf_counter()
print(t1 - t0, (t2 - t1) - (t3 - t2), tr.meta["build_time"])
"""


def one_time_costs(cold: bool) -> dict[str, float]:
    """Fresh processes: imports, first-call kernel load from the numba on-disk cache (and, if cold,
    the compile of every kernel into an empty cache), model build."""
    def run(env):
        res = subprocess.run([sys.executable, "-c", _COLD], capture_output=True, text=True, cwd=ROOT,
                             check=True, env=env)
        return [float(v) for v in res.stdout.split()[-3:]]

    run(None)  # make sure the regular cache is populated
    imports, first, build = run(None)
    out = {"imports": imports, "first_call_cached": first, "build": build}
    if cold:
        with tempfile.TemporaryDirectory() as tmp:
            out["first_call_cold"] = run({**os.environ, "TELEOP_CACHE_DIR": tmp})[1]
    return out


# ---------------------------------------------------------------------------------------------
def _pin(cpu: int) -> str:
    if cpu < 0 or not hasattr(os, "sched_setaffinity"):
        return "not pinned"
    cpus = sorted(os.sched_getaffinity(0))
    c = cpus[cpu] if cpu < len(cpus) else cpus[-1]
    os.sched_setaffinity(0, {c})
    return f"pinned to CPU {c}"


def _machine() -> str:
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{os.cpu_count()} CPUs (nproc), {model}; Python {platform.python_version()}, MuJoCo "
            f"{mujoco.__version__}, numba {numba.__version__}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="2 s runs instead of the 20 s paper scenario")
    ap.add_argument("--segments", default="4,8,16,32", help="N values for the scaling table")
    ap.add_argument("--reps", type=int, default=3, help="repetitions (best of)")
    ap.add_argument("--cpu", type=int, default=-1 if os.cpu_count() == 1 else 1,
                    help="index of the CPU to pin to (-1: no pinning)")
    ap.add_argument("--no-write", action="store_true", help="do not write benchmarks/results/bench_loop.md")
    ap.add_argument("--no-cold", action="store_true", help="skip the empty-cache compile timing (~1 min)")
    args = ap.parse_args()
    pinned = _pin(args.cpu)
    dur = 2.0 if args.quick else 20.0
    base = Scenario(duration=dur)
    lines: list[str] = []

    def out(s: str = "") -> None:
        print(s, flush=True)
        lines.append(s)

    cold = one_time_costs(not args.no_cold)
    # warm up every compiled kernel (numba cache or first compile) in this process
    for act in ("servo", "torque"):
        simulate_mujoco(dataclasses.replace(base, duration=0.05, plant=PlantConfig(actuation=act)))
    simulate_analytic(dataclasses.replace(base, duration=0.05, plant=PlantConfig(kind="analytic")))

    out("# Harness speed vs raw MuJoCo\n")
    out(f"Machine: {_machine()}; benchmark process {pinned} (one core for everything, including Rerun's "
        f"writer thread); {args.reps} interleaved repetitions.\n")
    out(f"Paper scenario: {dur:g} s at 1 kHz (1 ms physics = control step), N = {base.plant.segments} "
        f"segments/section, servo on the default plant ({_cc(base)}), torque on the CC chain (the free "
        f"chain diverges in torque mode, README), SNR {base.snr_db} dB noise, both controllers with "
        "the null-space terms, record row every step.  'raw' = the same physics steps (logged commands "
        "replayed from the same initial state, compiled loop calling the C mj_step).  Times are the best "
        "of the repetitions, per control step; ratios are best / best and, in brackets, the median of "
        "the ratios of back-to-back pairs (the machine's speed drifts by up to ~40 % between runs).\n")
    out("| actuation | raw mj_step | harness loop | loop / raw | + recording geometry | + .rrd written | "
        "total / raw | .rrd write alone |")
    out("|---|---|---|---|---|---|---|---|")
    results = {}
    for act in ("servo", "torque"):
        cc = base.plant.enforce_cc or act == "torque"
        scn = dataclasses.replace(base, plant=dataclasses.replace(base.plant, actuation=act, enforce_cc=cc))
        r = harness_vs_raw(scn, args.reps, rrd=True)
        results[act] = r
        us = {k: best_us(r, k) for k in ("raw", "loop", "sim", "total", "rrd_write")}
        note = "" if r["status"] == "ok" else f" ({r['status']})"
        out(f"| {act}{note} | {us['raw']:.1f} us | {us['loop']:.1f} us | **{us['loop'] / us['raw']:.2f}x** "
            f"({paired_ratio(r, 'loop'):.2f}x) | {us['sim']:.1f} us | {us['total']:.1f} us | "
            f"**{us['total'] / us['raw']:.2f}x** ({paired_ratio(r, 'total'):.2f}x) | "
            f"{us['rrd_write']:.1f} us |")
    out("\n'recording geometry' = loop + MuJoCo body/site poses (copied in the loop from the kinematics "
        "mj_step computed) + analytic backbone + Trajectory, i.e. simulate_mujoco's wall time without the "
        "model build; '.rrd written' adds write_recording (every step logged, file flushed).\n")
    r = results["servo"]
    text = (f"One-time costs (fresh process): imports {cold['imports']:.2f} s; first simulate call (the "
            f"ahead-of-time kernels, or numba's on-disk cache) {cold['first_call_cached']:.2f} s")
    if "first_call_cold" in cold:
        text += f"; with an empty cache (compiles everything once) {cold['first_call_cold']:.1f} s"
    text += (f"; model build {np.min(r['build']) * 1e3:.0f} ms per run; recording geometry after the loop "
             f"{best_us(r, 'geometry'):.1f} us per step (backbone; included above).\n")
    out(text)

    an = dataclasses.replace(base, plant=PlantConfig(kind="analytic"))
    best = min(simulate_analytic(an).meta["wall_time"] for _ in range(args.reps))
    out(f"Analytic plant (both laws + RK4 of the analytic models, 1 RK4 step per control step): "
        f"{best / an.n_steps * 1e6:.1f} us per control step, {dur / best:.0f}x real time.\n")

    scn = dataclasses.replace(base, duration=min(dur, 2.0))
    parts = parts_us(scn, results["servo"]["log"][:scn.n_steps * scn.substeps], max(args.reps, 5))
    r = results["servo"]
    loop_us, raw_us = best_us(r, "loop"), best_us(r, "raw")
    top = sum(v for k, v in parts.items() if not k.startswith(" "))
    out("Where the harness loop's time goes beyond mj_step (servo, each piece in a compiled loop over the "
        f"recorded states of the first {scn.duration:g} s, us per control step):\n")
    out("| piece | us/step |\n|---|---|")
    for k, v in parts.items():
        out(f"| {k.strip() if not k.startswith(' ') else '&nbsp;&nbsp;' + k.strip()} | {v:.2f} |")
    out(f"| **sum of the pieces** | **{top:.2f}** |")
    out(f"| harness loop - raw mj_step (measured above) | {loop_us - raw_us:.2f} |")
    out(f"| rest: loop bookkeeping, per-chunk Python and numba dispatch, interleaving with mj_step (caches), "
        f"machine drift | {loop_us - raw_us - top:.2f} |")

    settings_table(base, args.reps, out)

    out("\nCost vs segments per section N (2 s runs, CC constraints on unless stated; us per control "
        "step):\n")
    out("| N | CC | actuation | nv | raw mj_step | harness loop | loop / raw | + rec. geometry | note |")
    out("|---|---|---|---|---|---|---|---|---|")
    for n_seg in [int(v) for v in args.segments.split(",")]:
        for cc in (True, False):
            for act in ("servo", "torque"):
                scn = dataclasses.replace(base, duration=min(dur, 2.0),
                                          plant=dataclasses.replace(base.plant, segments=n_seg, enforce_cc=cc,
                                                                    actuation=act))
                m, _, _ = make_plant(scn)
                if cc:
                    r = harness_vs_raw(scn, args.reps, rrd=False)
                    raw, loop, sim = (best_us(r, k) for k in ("raw", "loop", "sim"))
                    note = "" if r["status"] == "ok" else f"{r['status']}: {r['message'][:50]}"
                    out(f"| {n_seg} | on | {act} | {m.nv} | {raw:.1f} us | {loop:.1f} us | "
                        f"{loop / raw:.2f}x ({paired_ratio(r, 'loop'):.2f}x) | {sim:.1f} us | {note} |")
                else:
                    tr = simulate_mujoco(scn)
                    steps = 2000
                    raw = min(raw_hold_s(scn, steps) for _ in range(args.reps)) / steps * 1e6
                    note = (f"harness {tr.status} at t = {tr.t[-1]:.3f} s; raw = servos holding q2(0)"
                            if tr.status != "ok" else "raw = servos holding q2(0)")
                    if act == "torque":
                        note += " (torque: zero commands, chain falls under gravity)"
                    out(f"| {n_seg} | off | {act} | {m.nv} | {raw:.1f} us | - | - | - | {note} |")
    if not args.no_write:
        from results import write_result

        write_result(__file__, "\n".join(lines))


if __name__ == "__main__":
    main()
