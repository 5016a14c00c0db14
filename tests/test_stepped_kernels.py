"""The stepped loop's compiled glue (harness.loop.stepped_kernels) and the Cosserat plant's deferred
recording (CosseratPlant.record / finish) give the numbers of the code they replace."""

from __future__ import annotations

import numpy as np
import pytest

from harness.config.load import load_scenario
from harness.loop.common import compile_model
from harness.loop.fast import kernels
from harness.loop.kernels import R_E1, R_E2, RUNAWAY
from harness.loop.stepped_loop import simulate_stepped
from harness.loop.trajectory import ROW_SLICES, ROW_WIDTH
from harness.plant import build_plant


def _check_numpy(state, exploding, Ftrue, Fctl, ignored):
    """The loop's former numpy statements (reference for stepped_state_check)."""
    total = float(state @ state)
    if not np.isfinite(total) or total > exploding * exploding:
        return 8
    if min(state[4], state[5], state[6]) <= 0.0:
        return 5
    Fctl[:] = 0.0 if ignored else Ftrue
    return 0


def _after_numpy(st, T1, T2, u2, row, Ftrue, Fsens, cinfo, ref_mode, ext, ref, dt, sensed, cmd):
    """The loop's former numpy statements (reference for stepped_after_control)."""
    row[ROW_SLICES["F_true"]] = Ftrue
    row[ROW_SLICES["F_sensed"]] = Fsens
    row[ROW_SLICES["contact"]] = cinfo
    if st == 0 and not np.isfinite(float(T1.sum() + T2.sum() + u2.sum())):
        st = 1
    if st == 0 and (abs(row[R_E1]) + abs(row[R_E1 + 1]) > RUNAWAY
                    or abs(row[R_E2]) + abs(row[R_E2 + 1]) > RUNAWAY):
        st = 4
    if st != 0:
        return st
    if ref_mode == 1:
        ref[6:12] += u2 * dt
        ref[0:6] += ref[6:12] * dt
    elif ref_mode == 2:
        ref[:] = ext
    cmd[0:2], cmd[2:8], cmd[8:20], cmd[20:26] = T1, T2, ref, sensed[4:10]
    return 0


@pytest.mark.parametrize("jit", [True, False])
def test_state_check_kernel_equals_numpy(jit):
    Kx = kernels(jit)
    rng = np.random.default_rng(3)
    cases = [rng.normal(size=16) for _ in range(20)]
    for state in cases:
        state[4:7] = np.abs(state[4:7]) + 0.1
    cases[0][5] = -0.1  # section length <= 0
    cases[1][4] = 0.0
    cases[2][9] = np.nan
    cases[3][0] = np.inf
    cases[4][12] = 2e6  # exploding
    for state in cases:
        for ignored in (False, True):
            Ftrue = rng.normal(size=4)
            a, b = np.full(4, 7.0), np.full(4, 7.0)
            sa = Kx.stepped_state_check(state, 1e6, Ftrue, a, ignored)
            sb = _check_numpy(state, 1e6, Ftrue, b, ignored)
            assert sa == sb
            assert np.array_equal(a, b)
    assert Kx.stepped_state_check(cases[0], 1e6, np.zeros(4), np.zeros(4), False) == 5
    assert Kx.stepped_state_check(cases[2], 1e6, np.zeros(4), np.zeros(4), False) == 8
    assert Kx.stepped_state_check(cases[4], 1e6, np.zeros(4), np.zeros(4), False) == 8


@pytest.mark.parametrize("jit", [True, False])
def test_after_control_kernel_equals_numpy(jit):
    Kx = kernels(jit)
    rng = np.random.default_rng(4)
    seen = set()
    cols = (ROW_SLICES["F_true"].start, ROW_SLICES["F_sensed"].start, ROW_SLICES["contact"].start)
    for i in range(60):
        T1, T2, u2 = rng.normal(size=2), rng.normal(size=6), rng.normal(size=6) * 10
        if i % 7 == 1:
            T2[3] = np.nan
        row = rng.normal(size=ROW_WIDTH) * 0.3
        if i % 5 == 2:
            row[R_E2 + 1] = 1.5  # runaway
        Ftrue, Fsens, cinfo = rng.normal(size=4), rng.normal(size=4), rng.normal(size=5)
        ext, sensed = rng.normal(size=12), rng.normal(size=16)
        ref0 = rng.normal(size=12)
        st0 = 3 if i % 11 == 3 else 0
        mode = i % 3
        outs = []
        for f in ("kernel", "numpy"):
            r, ref, cmd = row.copy(), ref0.copy(), np.full(26, 9.0)
            if f == "kernel":
                s = Kx.stepped_after_control(st0, T1, T2, u2, r, Ftrue, Fsens, cinfo, *cols, mode, ext, ref,
                                             1e-3, sensed, cmd)
            else:
                s = _after_numpy(st0, T1, T2, u2, r, Ftrue, Fsens, cinfo, mode, ext, ref, 1e-3, sensed, cmd)
            outs.append((s, r, ref, cmd))
        assert outs[0][0] == outs[1][0]
        seen.add(outs[0][0])
        for x, y in zip(outs[0][1:], outs[1][1:], strict=True):
            assert np.array_equal(x, y)  # bit for bit, not just close
    assert seen == {0, 1, 3, 4}  # every branch exercised


class _PerStepGeometry:
    """A Cosserat plant seen without record / finish: the loop asks slave_tip() and geometry() per step."""

    def __init__(self, plant):
        self.plant = plant

    def __getattr__(self, name):
        if name in ("record", "finish"):
            raise AttributeError(name)
        return getattr(self.plant, name)


@pytest.mark.parametrize("extra", [[], ["plant.actuation=torque"]])
def test_cosserat_deferred_recording_equals_per_step_geometry(extra):
    scn = load_scenario(None, ["duration=0.05", "transient=0", "plant.kind=cosserat", *extra])
    a = simulate_stepped(scn, build_plant(scn))
    b = simulate_stepped(scn, _PerStepGeometry(build_plant(scn)))
    assert a.status == b.status == "ok" and len(a) == len(b) == scn.n_steps
    assert np.array_equal(a.x2_plant, b.x2_plant)
    assert np.array_equal(a.master_pos, b.master_pos)
    assert a.meta["geometry"].keys() == b.meta["geometry"].keys() == {"centreline", "sections"}
    for k in a.meta["geometry"]:
        assert np.array_equal(a.meta["geometry"][k], b.meta["geometry"][k])
        assert a.meta["geometry"][k].flags.c_contiguous
    assert np.array_equal(a.q2, b.q2)
    # the tip is the last centreline node (the slave base is offset along Y only)
    np.testing.assert_array_equal(a.x2_plant, a.meta["geometry"]["centreline"][:, -1, [0, 2]])


def test_cosserat_plant_built_for_a_shorter_run_records_a_longer_one():
    """The deferred recording's buffers are sized from the scenario the plant was built for; a plant
    built for 0.02 s and run for 0.05 s records every step, the same numbers as a plant built for it."""
    short = load_scenario(None, ["duration=0.02", "transient=0", "plant.kind=cosserat"])
    scn = load_scenario(None, ["duration=0.05", "transient=0", "plant.kind=cosserat"])
    a = simulate_stepped(scn, build_plant(short))
    b = simulate_stepped(scn, build_plant(scn))
    assert a.status == b.status == "ok" and len(a) == len(b) == scn.n_steps
    assert np.array_equal(a.x2_plant, b.x2_plant)
    for k in b.meta["geometry"]:
        assert np.array_equal(a.meta["geometry"][k], b.meta["geometry"][k])


def test_rod_command_kernels_equal_the_numpy_expressions():
    """cosserat_rod.rest_strains / active_loads (the servo rest strains and the active loads of
    harness.plant.cosserat, Actuation) give the numbers of the numpy expressions they replaced, bit for
    bit."""
    from harness.plant import cosserat_rod as kr

    rng = np.random.default_rng(5)
    n = 7
    L0 = np.array([0.3, 0.25, 0.2])
    sec = np.repeat(np.arange(3), n)
    l0 = (L0 / n)[sec]
    ne = 3 * n
    for i in range(40):
        q2 = np.concatenate([L0 * rng.uniform(0.8, 1.4, 3), rng.normal(size=3) * (3.0 if i % 4 else 1e-9)])
        if i == 0:
            q2[3:] = 0.0  # straight sections: sinc limit
        T2 = rng.normal(size=6)
        # reference: the former numpy code of CosseratSlave._set_rest / _set_active
        d, k = q2[:3], q2[3:]
        x = 0.5 * k * (d / n)
        sinc = np.where(np.abs(x) < 1e-8, 1.0 - x * x / 6.0, np.sin(x) / np.where(x == 0, 1.0, x))
        sig_ref = np.zeros((3, ne))
        sig_ref[2] = (d / L0 * sinc - 1.0)[sec]
        kap = (k * d / L0)[sec]
        kap_ref = np.zeros((3, ne - 1))
        kap_ref[1] = (l0[:-1] * kap[:-1] + l0[1:] * kap[1:]) / (l0[:-1] + l0[1:])
        mu = T2[3:] / d
        n_ref = (T2[:3] - k * mu)[sec]
        m_ref = np.zeros((3, ne - 1))
        mue = mu[sec]
        m_ref[1] = (l0[:-1] * mue[:-1] + l0[1:] * mue[1:]) / (l0[:-1] + l0[1:])
        sig, kp, kb = np.full((3, ne), 9.0), np.full((3, ne - 1), 9.0), np.full(3, 9.0)
        kr.rest_strains(q2, n, L0, sec, l0, sig, kp, kb)
        an, am, amb = np.full(ne, 9.0), np.full((3, ne - 1), 9.0), np.full(3, 9.0)
        kr.active_loads(T2, q2, sec, l0, an, am, amb)
        assert np.array_equal(sig, sig_ref) and np.array_equal(kp, kap_ref)
        assert np.array_equal(kb, [0.0, kap[0], 0.0])
        assert np.array_equal(an, n_ref) and np.array_equal(am, m_ref)
        assert np.array_equal(amb, [0.0, mu[0], 0.0])


@pytest.mark.parametrize("extra", [["sensing.force.mode=ignored"], ["plant.actuation=servo", "snr_db=none"]])
def test_the_three_controller_paths_of_the_stepped_loop_agree(extra):
    """The paper controller's one-call step (stepped_paper_step), its fused_step (a subclass) and its
    generic step() give the same rows bit for bit (constant interaction forces, actuation delay)."""
    from harness.loop.stepped_loop import PaperController
    from harness.loop.stepped_plants import stepped_plant

    class Fused(PaperController):
        pass

    class Plain(PaperController):
        fused_step = None

    scn = load_scenario(None, ["plant.kind=mujoco", "duration=0.3", "plant.actuation_delay=0.002",
                               "interaction_forces=[[0.5, -1.0], [0.2, 0.4]]", *extra])
    ctrls = (PaperController, Fused, Plain)
    runs = [simulate_stepped(scn, stepped_plant(scn, compile_model(scn)), controller=c()) for c in ctrls]
    assert all(r.status == "ok" and len(r) == scn.n_steps for r in runs)
    for f in ("q1", "q2", "T1", "T2", "u2", "F_true", "F_sensed", "e2"):
        for r in runs[1:]:
            assert np.array_equal(getattr(runs[0], f), getattr(r, f)), f
    if "sensing.force.mode=ignored" in extra:
        assert np.all(runs[0].F_sensed == 0.0) and np.any(runs[0].F_true != 0.0)
