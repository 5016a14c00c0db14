"""The stepped loop's paths agree (the paper's fast path and the interface), and the Cosserat plant's deferred
recording (CosseratPlant.record / finish) gives the numbers of per-step geometry, and the rod's command
kernels do what they stand for: the servo's rest strains lay the rod on the commanded arcs, the active
loads do the generalized forces' virtual work."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from harness.config.load import load_scenario
from harness.loop.common import compile_model
from harness.loop.stepped_loop import simulate_stepped
from harness.plant import build_plant

CONTACT = Path(__file__).resolve().parent.parent / "scenarios" / "contact.toml"


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


def _rod_layout(n=7):
    L0 = np.array([0.3, 0.25, 0.2])
    sec = np.repeat(np.arange(3), n)
    return n, L0, sec, (L0 / n)[sec]


def _random_q2(rng, L0, i):
    q2 = np.concatenate([L0 * rng.uniform(0.8, 1.4, 3), rng.normal(size=3) * (3.0 if i % 4 else 1e-9)])
    if i == 0:
        q2[3:] = 0.0  # straight sections: the sinc limit
    return q2


def test_rest_strains_lay_the_rod_on_the_commanded_arcs():
    """cosserat_rod.rest_strains (the servo's rest shape): a rod at rest with these strains is the
    commanded constant-curvature arcs cut into n elements per section.  Reference: the nodes of the arcs
    at j/n of each section (conftest.cc_shape, written independently): each element's rest length
    l0 (1 + sigma_z) is the chord between its nodes, and the rest curvature at each hinge times its
    Voronoi length l0 is the angle between the neighbouring chords (at the base: between the base
    direction and the first chord, over half an element)."""
    from conftest import cc_shape

    from harness.plant.cosserat import kernels as kr

    n, L0, sec, l0 = _rod_layout()
    ne = 3 * n
    rng = np.random.default_rng(5)
    for i in range(40):
        q2 = _random_q2(rng, L0, i)
        sig, kp, kb = np.full((3, ne), 9.0), np.full((3, ne - 1), 9.0), np.full(3, 9.0)
        kr.rest_strains(q2, n, L0, sec, l0, sig, kp, kb)
        chords = np.diff(cc_shape(q2, per_section=n), axis=0)  # (ne, 2) [x, z]
        np.testing.assert_allclose(l0 * (1.0 + sig[2]), np.hypot(*chords.T), rtol=1e-12, atol=1e-15)
        assert not sig[:2].any() and not kp[[0, 2]].any() and not kb[[0, 2]].any()
        a, b = chords[:-1], chords[1:]
        turn = np.arctan2(a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1], (a * b).sum(1))
        np.testing.assert_allclose(kp[1] * 0.5 * (l0[:-1] + l0[1:]), turn, rtol=1e-9, atol=1e-13)
        first = np.arctan2(chords[0, 0], chords[0, 1])  # from the base direction (+z)
        np.testing.assert_allclose(kb[1] * 0.5 * l0[0], first, rtol=1e-9, atol=1e-13)


def test_active_loads_do_the_virtual_work_of_the_generalized_forces():
    """cosserat_rod.active_loads: the internal axial force n and bending moment m it sets do, per unit rest
    length of section i, the virtual work of the generalized forces, (T_d dd + T_k dk) / L0, for every
    virtual change dq2 of the arc (axial strain d / L0 - 1, curvature k d / L0 per rest length)."""
    from harness.plant.cosserat import kernels as kr

    n, L0, sec, l0 = _rod_layout()
    ne = 3 * n
    rng = np.random.default_rng(6)
    inner = np.flatnonzero(sec[:-1] == sec[1:])  # hinges inside a section
    for i in range(40):
        q2, T2, dq = _random_q2(rng, L0, i), rng.normal(size=6), rng.normal(size=6)
        an, am, amb = np.full(ne, 9.0), np.full((3, ne - 1), 9.0), np.full(3, 9.0)
        kr.active_loads(T2, q2, sec, l0, an, am, amb)
        d, k, dd, dk = q2[:3], q2[3:], dq[:3], dq[3:]
        want = (T2[:3] * dd + T2[3:] * dk) / L0
        m_sec = np.full(3, np.nan)
        m_sec[sec[inner]] = am[1, inner]
        np.testing.assert_allclose(amb[1], m_sec[0], rtol=1e-15)
        assert not am[[0, 2]].any() and not amb[[0, 2]].any()
        work = an * (dd / L0)[sec] + (m_sec * (k * dd + d * dk) / L0)[sec]
        np.testing.assert_allclose(work, want[sec], rtol=1e-10, atol=1e-12 * np.abs(want).max())


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


@pytest.mark.parametrize("case", ["forces", "contact"])
def test_python_stepped_mujoco_plant_equals_the_compiled_loop_with_interaction_forces(case):
    """The Python-stepped MuJoCo plant feels the constant tip forces (F1 through J1^T F1, F2 on the tip body)
    and reads the contact sensors as the compiled loop does: the paper's law through the interface
    ("paper_interface", Python-stepped) gives the compiled loop's ("paper") rows bit for bit."""
    from harness.loop import simulate

    contact = ["duration=0.6", "transient=0", "operator.enabled=false", "sensing.force.mode=exact"]
    path, extra = {"forces": (None, ["duration=0.3", "interaction_forces=[[0.5, -1.0], [0.2, 0.4]]"]),
                   "contact": (CONTACT, contact)}[case]
    a, b = (simulate(load_scenario(path, [*extra, f"controller.name={c}"]))
            for c in ("paper", "paper_interface"))
    assert a.status == b.status == "ok" and len(a) == len(b)
    for f in ("q1", "q2", "T1", "T2", "u2", "F_true", "F_sensed", "contact", "x2_plant", "body_pos"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    if case == "contact":
        assert np.any(a.contact[:, 0] > 0)  # the arm touches the ceiling


def test_python_stepped_mujoco_plant_refuses_what_it_does_not_simulate():
    from harness.config.errors import ConfigError
    from harness.loop import simulate

    with pytest.raises(ConfigError, match="operator.enabled"):
        simulate(load_scenario(CONTACT, ["duration=0.1", "transient=0", "controller.name=paper_interface"]))


def test_python_stepped_mujoco_plant_reports_mujoco_warnings_as_the_compiled_loop(tmp_path, capfd):
    """A controller commanding a finite master torque beyond MuJoCo's limit (1e11 > mjMAXVAL) at step 3:
    MuJoCo raises mjWARN_BADCTRL inside that step's mj_step; the Python-stepped run stops there with status
    7 and, as the compiled loop, names the warning and MuJoCo's own text in the message and keeps the text
    in meta["mujoco_warning_text"] instead of printing it."""
    from harness.loop import simulate

    p = tmp_path / "huge.py"
    p.write_text("import numpy as np\n"
                 "from controllers.baselines import PaperNoNullSpace\n"
                 "class Huge(PaperNoNullSpace):\n"
                 "    def step(self, obs):\n"
                 "        act = super().step(obs)\n"
                 "        if obs.k == 3:\n"
                 "            act.T1 = np.array([1e11, 0.0])\n"
                 "        return act\n")
    tr = simulate(load_scenario(None, ["duration=0.1", f'controller.name="{p}:Huge"']))
    assert tr.status == "diverged", tr.message
    assert tr.message.startswith("MuJoCo warning (mjWARN_BADCTRL: 1); MuJoCo says: "), tr.message
    assert tr.message.endswith(f"at t = {tr.t[-1]:.4f} s") and len(tr) == 4
    assert tr.meta["mujoco_warnings"] == 1 and tr.meta["mujoco_warning_counts"] == {"mjWARN_BADCTRL": 1}
    text = tr.meta["mujoco_warning_text"]
    assert len(text) == 1 and text[0].strip() in tr.message
    out, err = capfd.readouterr()
    assert text[0].strip() not in out + err
