"""Environment contact on the Cosserat plant: PyElastica's penalty law on every rod node
(harness/plant/cosserat/contact.py, compiled in harness/plant/cosserat/kernels.py).  A static tip push
against a
plane settles at the penetration the closed form predicts (wall spring k in parallel with the rod's
axial stiffness), the contact force equals k times the geometric penetration, a sphere beside the
middle of the rod is touched by body nodes while the tip is free, the stepped loop records the tip
contact force, and unsupported or intersecting objects are one-line errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import EnvironmentConfig, EnvObject
from harness.loop.stepped_loop import simulate_stepped
from harness.plant import build_plant
from harness.plant.cosserat import NODE_RADIUS, CosseratSlave, contact_arrays
from harness.plant.initial import initial_state

N_EL = 6  # elements per section


def _straight_rod(env: EnvironmentConfig):
    """A straight rod along +Z (servo held at its rest shape), no gravity, with env's objects."""
    p = load_scenario(None, []).plant_slave
    p = dataclasses.replace(p, gravity=(0.0, 0.0))
    rod = CosseratSlave(p, N_EL, actuation="servo")
    q2 = np.concatenate([np.asarray(p.rest_lengths, dtype=float), np.zeros(3)])
    rod.reset(q2)
    rod.set_contacts(*contact_arrays(env, rod._b.mass))
    return rod, p, q2


@pytest.mark.parametrize("k, F", [(2.0e3, 4.0), (2.0e4, 10.0)])
def test_static_tip_push_against_plane(k, F):
    """Tip force F (+Z) into a plane touching the tip ball (normal -Z): at rest the tip node penetrates
    g = F / (k + K), K = 1 / sum(1 / Ke_i) the rod's series axial stiffness (EA / L0 = Ke per section),
    and the plane pushes back with k g (the MuJoCo plant's Hooke law)."""
    env0 = EnvironmentConfig()
    rod, p, q2 = _straight_rod(env0)
    tip_z = rod.tip()[1]
    wall = EnvObject(name="wall", kind="plane", position=(0.0, tip_z + NODE_RADIUS), normal=(0.0, -1.0),
                     stiffness=k, damping_ratio=1.0)
    rod.set_contacts(*contact_arrays(EnvironmentConfig(objects=(wall,)), rod._b.mass))
    rod.external_tip_force((0.0, F))
    for _ in range(40):
        assert rod.step(q2, 0.01)
    K = 1.0 / np.sum(1.0 / np.asarray(p.extension_stiffness, dtype=float))
    g = rod.tip()[1] - tip_z  # geometric penetration of the tip ball into the plane
    fz = rod.f_contact[2, -1]
    assert abs(g - F / (k + K)) < 0.01 * F / (k + K)
    assert abs(fz + k * g) < 1e-3 * k * g  # force ON the rod = -k g (Z), settled: no damping part left
    assert np.all(rod.f_contact[:, :-1] == 0.0)  # only the tip node touches


def test_body_contact_away_from_tip_is_detected():
    """A sphere pressing 5 mm into the middle of the straight rod: middle nodes carry the force (pushed
    toward -X), the tip node carries none, and the nodal forces are k times each node's penetration."""
    rod, p, q2 = _straight_rod(EnvironmentConfig())
    L = float(np.sum(p.rest_lengths))
    R, k = 0.03, 5.0e3
    ball = EnvObject(name="post", kind="sphere", position=(R + NODE_RADIUS - 0.005, 0.5 * L),
                     size=(R, R), stiffness=k, damping_ratio=1.0)
    rod.set_contacts(*contact_arrays(EnvironmentConfig(objects=(ball,)), rod._b.mass))
    assert rod.step(q2, 0.001)
    fc = rod.f_contact
    touching = np.nonzero(np.abs(fc[0]) > 0)[0]
    nn = fc.shape[1]
    assert touching.size >= 1 and touching.min() > 0 and touching.max() < nn - 1
    pos = rod._b.position_collection
    for j in touching:
        dx, dz = pos[0, j] - ball.position[0], pos[2, j] - ball.position[1]
        assert fc[0, j] < 0.0
        gj = R + NODE_RADIUS - np.hypot(dx, dz)
        assert gj > 0
    assert fc[0, -1] == 0.0 and fc[2, -1] == 0.0


def _scn(obj: dict, *over):
    return load_scenario({"plant": {"kind": "cosserat", "cosserat": {"elements_per_section": N_EL}},
                          "environment": {"objects": {"obj": obj}}}, list(over))


def test_box_on_cosserat_is_one_line_error():
    with pytest.raises(ConfigError) as ei:
        build_plant(_scn({"kind": "box", "position": [0.5, 0.5]}))
    msg = str(ei.value)
    assert "\n" not in msg and "environment.objects.obj.kind = 'box'" in msg and "PyElastica" in msg


def test_object_intersecting_rod_at_start_is_one_line_error():
    with pytest.raises(ConfigError) as ei:
        build_plant(_scn({"kind": "sphere", "position": [0.0, 0.5], "size": [0.05, 0.05]}))
    msg = str(ei.value)
    assert "\n" not in msg and "environment.objects.obj" in msg and "t = 0" in msg


def test_stepped_loop_records_tip_contact_force():
    """A plane just above the tip: the arm, tracking upward, presses it; F_true[:, 2:4] is the tip node's
    contact force (+ the constant F2 = 0), and the contact columns count nodes and the penetration."""
    scn0 = load_scenario(None, ["plant.kind=cosserat"])
    plant0 = build_plant(scn0)
    s0 = initial_state(scn0)
    plant0.slave.reset(s0[4:10])
    tip = plant0.slave.tip()
    scn = _scn({"kind": "plane", "position": [0.0, float(tip[1]) + NODE_RADIUS + 0.002],
                "normal": [0.0, -1.0], "stiffness": 2e3}, "duration=1.0", "sensing.force.mode=exact")
    plant = build_plant(scn)
    tr = simulate_stepped(scn, plant)
    assert tr.status == "ok", tr.message
    on = tr.contact[:, 4] == 1
    assert on.sum() > 10
    assert np.all(tr.F_true[~on, 2:4] == 0.0)
    assert np.all(tr.F_true[on, 3] != 0.0)
    np.testing.assert_array_equal(tr.F_sensed, tr.F_true)  # exact mode: the controller's F
    assert np.all(tr.contact[on, 3] < 0.0)
