"""The stepped loop's paths agree (the paper's fast path and the interface), and the Cosserat plant's deferred
recording (CosseratPlant.record / finish) gives the numbers of per-step geometry."""

from __future__ import annotations

import numpy as np
import pytest

from harness.config.load import load_scenario
from harness.loop.common import compile_model
from harness.loop.stepped_loop import simulate_stepped
from harness.plant import build_plant


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
    """cosserat.kernels.rest_strains / active_loads (the servo rest strains and the active loads of
    harness.plant.cosserat, Actuation) give the numbers of the numpy expressions they replaced, bit for
    bit."""
    from harness.plant.cosserat import kernels as kr

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
def test_paper_fast_path_and_interface_agree_in_the_stepped_loop(extra):
    """The paper's law under "paper" (the stepped loop's one compiled call per step) and under
    "paper_interface" (the same registered class stepped through the public interface) give the same rows
    bit for bit on the Python-stepped MuJoCo plant (constant interaction forces, actuation delay)."""
    from harness.loop.stepped_plants import stepped_plant

    base = ["plant.kind=mujoco", "duration=0.3", "plant.actuation_delay=0.002",
            "interaction_forces=[[0.5, -1.0], [0.2, 0.4]]", *extra]
    runs = []
    for name in ("paper", "paper_interface"):
        scn = load_scenario(None, [*base, f"controller.name={name}"])
        model = compile_model(scn)
        runs.append(simulate_stepped(scn, stepped_plant(scn, model), model=model))
    assert all(r.status == "ok" and len(r) == runs[0].t.shape[0] for r in runs)
    for f in ("q1", "q2", "T1", "T2", "u2", "F_true", "F_sensed", "e2"):
        assert np.array_equal(getattr(runs[0], f), getattr(runs[1], f)), f
    if "sensing.force.mode=ignored" in extra:
        assert np.all(runs[0].F_sensed == 0.0) and np.any(runs[0].F_true != 0.0)
