"""Cosserat-rod plant (harness.plant.cosserat): closed forms, CC fit, servo, determinism, validation."""

import numpy as np
import pytest

from controllers import slave
from controllers.params import SlaveParams
from harness.plant.cosserat import CosseratSlave, material_damping_from_slave, stable_dt
from harness.plant.cosserat import kernels as kr

P0 = SlaveParams(gravity=(0.0, 0.0))
Q2 = np.array([0.33, 0.36, 0.40, 2.0, -3.0, 4.0])


def _settle_couple(plant, M, chunks, chunk=0.01):
    """Uniform internal couple M on the whole rod = an end couple M (no axial load)."""
    for _ in range(chunks):
        q, _ = plant.sense()
        plant.step(np.concatenate([q[3:] * M, M * q[:3]]), chunk)
    return plant.sense()


def test_cc_fit_recovers_sampled_arc_exactly():
    for q2 in (Q2, np.array([0.45, 0.3, 0.45, np.pi / 2 / 0.45, -np.pi / 2 / 0.3, np.pi / 2 / 0.45])):
        for n in (3, 10, 25):
            pts = slave.backbone(P0, q2, n)
            q, dq = np.empty(6), np.empty(6)
            bounds = np.array([0, n, 2 * n, 3 * n])
            kr.cc_fit(np.ascontiguousarray(pts), np.zeros_like(pts), bounds, 16, q, dq)
            np.testing.assert_allclose(q, q2, rtol=0, atol=1e-12)
            assert np.all(dq == 0)


def test_reset_then_sense_and_tip_match_cc():
    plant = CosseratSlave(SlaveParams())
    dq2 = np.array([0.01, -0.02, 0.03, 0.5, -0.4, 0.3])
    plant.reset(Q2, dq2)
    q, dq = plant.sense()
    np.testing.assert_allclose(q, Q2, atol=1e-12)  # nodes exactly on the arcs
    np.testing.assert_allclose(dq, dq2, atol=1e-6)  # finite-difference node rates
    np.testing.assert_allclose(plant.tip(), slave.tip_position(SlaveParams(), Q2), atol=1e-12)
    tip_velocity = plant._b.velocity_collection[[0, 2], -1]
    np.testing.assert_allclose(tip_velocity, slave.jacobian(SlaveParams(), Q2) @ dq2, atol=1e-6)
    c = plant.centreline()
    assert c.shape == (31, 3) and np.all(c[:, 1] == 0)
    np.testing.assert_array_equal(plant.section_nodes, [0, 10, 20, 30])


def _fresh_fit(plant):
    b = plant._b
    xz = np.ascontiguousarray(b.position_collection[[0, 2]].T)
    vxz = np.ascontiguousarray(b.velocity_collection[[0, 2]].T)
    q, dq = np.empty(6), np.empty(6)
    kr.cc_fit(xz, vxz, plant.section_nodes, 16, q, dq)
    return q, dq


def test_cached_fit_follows_every_step_and_reset():
    """sense() keeps its CC fit until the rod moves: after each step and each reset it equals a fresh
    fit of the nodes, bit for bit, and it changes when the rod does."""
    plant = CosseratSlave(SlaveParams())
    plant.reset(Q2)
    q_before, _ = plant.sense()
    for _ in range(3):
        plant.step(Q2 + np.array([0.01, 0, 0, 0.5, 0, 0]), 0.002)
        q, dq = plant.sense()
        fq, fdq = _fresh_fit(plant)
        np.testing.assert_array_equal(q, fq)
        np.testing.assert_array_equal(dq, fdq)
    assert not np.array_equal(q, q_before)
    q2b = np.array([0.30, 0.34, 0.38, -1.0, 2.0, -2.0])
    plant.reset(q2b)
    q, dq = plant.sense()
    np.testing.assert_array_equal(q, _fresh_fit(plant)[0])
    np.testing.assert_allclose(q, q2b, atol=1e-12)
    q[:] = 0.0  # the caller owns what it gets: the cache is not aliased
    np.testing.assert_allclose(plant.sense()[0], q2b, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("law", ["analytic", "linear"])
def test_end_couple_gives_circular_arc(law):
    p = SlaveParams(gravity=(0.0, 0.0), bending_stiffness=(3.0, 3.0, 3.0))
    plant = CosseratSlave(p, actuation="torque", material_damping=(1.0, 1.0), elastic_law=law)
    M = 2.0
    q, dq = _settle_couple(plant, M, 300)
    k = M / 3.0
    assert np.max(np.abs(dq)) < 1e-3
    np.testing.assert_allclose(q[3:], k, rtol=0.01)
    L0, Ke = np.array(p.rest_lengths), np.array(p.extension_stiffness)
    # analytic law: a pure moment extends a section by Kb k^2 / (2 Ke); linear: no extension
    d = L0 + (3.0 * k * k / (2 * Ke) if law == "analytic" else 0.0)
    np.testing.assert_allclose(q[:3], d, rtol=1e-3)
    tip = slave.tip_position(p, np.concatenate([d, [k, k, k]]))
    assert np.linalg.norm(plant.tip() - tip) < 0.01 * d.sum()


def test_axial_force_extends_by_F_over_EA():
    p = P0
    plant = CosseratSlave(p, actuation="torque", material_damping=(0.5, 10.0))
    F = 20.0
    plant.external_tip_force([0.0, F])
    for _ in range(20):
        plant.step(np.zeros(6), 0.05)
    q, _ = plant.sense()
    strain = (q[:3] - np.array(p.rest_lengths)) / np.array(p.rest_lengths)
    np.testing.assert_allclose(strain, F / (np.array(p.extension_stiffness) * np.array(p.rest_lengths)),
                               rtol=0.01)
    np.testing.assert_allclose(q[3:], 0.0, atol=1e-9)


@pytest.mark.slow
def test_servo_reaches_command():
    start = Q2 + np.array([0.02, -0.02, 0.02, -0.5, 0.5, -0.5])
    plant = CosseratSlave(P0, material_damping=(0.3, 3.0))
    plant.reset(start)
    for _ in range(50):
        plant.step(Q2, 0.1)
    q, dq = plant.sense()
    np.testing.assert_allclose(q, Q2, atol=2e-3)
    assert np.linalg.norm(plant.tip() - slave.tip_position(P0, Q2)) < 1e-3
    # under gravity the sections' own stiffness sags: the departure is the static deflection
    g = CosseratSlave(SlaveParams(), material_damping=(0.3, 3.0))
    g.reset(Q2)
    for _ in range(50):
        g.step(Q2, 0.1)
    dep = np.linalg.norm(g.tip() - slave.tip_position(SlaveParams(), Q2))
    print("servo departure under gravity (m):", dep)
    assert 0.005 < dep < 0.15


def test_same_inputs_same_numbers_and_pyelastica_stepper_agrees():
    runs = []
    for stepper in ("numba", "numba", "pyelastica"):
        plant = CosseratSlave(SlaveParams(), stepper=stepper)
        plant.reset(Q2)
        plant.external_tip_force([0.3, -0.2])
        for i in range(5):
            plant.step(Q2 + 0.01 * i, 0.001, feedforward=np.full(6, 0.1))
        runs.append(np.concatenate([plant.centreline().ravel(), *plant.sense()]))
    np.testing.assert_array_equal(runs[0], runs[1])
    np.testing.assert_allclose(runs[2], runs[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kwargs, field", [
    (dict(dt=1e-3), "plant.cosserat.dt = 0.001: too large for 10 elements per section, must be <="),
    (dict(params=SlaveParams(bending_stiffness=(8.0, 0.0, 1.0))), "plant.cosserat.slave.bending_stiffness"),
    (dict(params=SlaveParams(extension_stiffness=(0.0, 1.0, 1.0))),
     "plant.cosserat.slave.extension_stiffness"),
    (dict(elements_per_section=1), "plant.cosserat.elements_per_section = 1"),
    (dict(actuation="force"), "plant.cosserat.actuation = 'force'"),
    (dict(material_damping=(-1.0, 0.1)), "plant.cosserat.material_damping"),
    (dict(shear_factor=0.0), "plant.cosserat.shear_factor = 0.0"),
    (dict(params=SlaveParams(rest_lengths=(-0.3, 0.3, 0.3))), "plant.cosserat.slave.rest_lengths"),
    (dict(params=SlaveParams(masses=(0.0, 0.7, 0.4))), "plant.cosserat.slave.masses"),
    (dict(params=SlaveParams(slice_inertia=(-1.0, 0.0, 0.0))), "plant.cosserat.slave.slice_inertia"),
])
def test_bad_settings_one_line_error(kwargs, field):
    kw = dict(params=SlaveParams())
    kw.update(kwargs)
    with pytest.raises(ValueError) as e:
        CosseratSlave(**kw)
    msg = str(e.value)
    assert msg.startswith(field) and "\n" not in msg


def test_bad_step_duration_and_helpers():
    plant = CosseratSlave(SlaveParams())
    with pytest.raises(ValueError, match=r"^plant.cosserat.duration"):
        plant.step(Q2, 0.3 * plant.dt)
    eta_b, eta_a = material_damping_from_slave(SlaveParams(bending_damping=(0.01, 0.01, 0.01)))
    np.testing.assert_allclose(eta_b, 0.01 / 0.3)
    assert stable_dt(SlaveParams(), 20) < stable_dt(SlaveParams(), 10)


def test_missing_pyelastica_internals_are_a_one_line_error():
    """The PyElastica internals sit behind one adapter: without them, one line naming the installed and the
    supported versions (checked in a fresh interpreter with elastica._linalg emptied)."""
    import subprocess
    import sys

    code = ("import sys, types\n"
            "import elastica\n"
            "sys.modules['elastica._linalg'] = types.ModuleType('elastica._linalg')\n"
            "try:\n"
            "    import harness.plant.cosserat.pyelastica\n"
            "except ImportError as exc:\n"
            "    print(type(exc).__name__, exc)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    line = res.stdout.strip()
    assert "\n" not in line and line.startswith("PyElasticaVersionError"), line
    from importlib.metadata import version
    assert f"installed pyelastica {version('pyelastica')}" in line and "supported pyelastica>=1.0,<2" in line
