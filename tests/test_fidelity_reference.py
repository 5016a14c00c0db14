"""Material damping of the MuJoCo chain vs the rod (closed-form dissipation, modal damping against the
Cosserat rod), the per-channel AWGN model, the worst-case tip error by optimization and the
gains x damping stability map (harness.plant.chain_params, harness.loop.kernels,
harness.studies.fidelity_reference, harness.studies.stability_map)."""

import numpy as np
import pytest

from controllers.params import MasterParams, SlaveParams
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import PlantConfig
from harness.loop import kernels
from harness.plant.mujoco_model import build_model
from harness.studies import fidelity_reference as fr

ETA_B = (0.02, 0.01, 0.005)  # N m^2 s
ETA_A = (0.5, 0.3, 0.2)  # N s


def _chain(N=8, slave=None, eta_b=ETA_B, eta_a=ETA_A):
    slave = SlaveParams() if slave is None else slave
    m, cm = build_model(MasterParams(), slave, PlantConfig(segments=N, bending_viscosity=eta_b,
                                                           extension_viscosity=eta_a))
    return m, cm, np.asarray(m.dof_damping)[np.asarray(cm.chain_dof_adr)]


@pytest.mark.parametrize("N", [1, 4, 8, 13])
def test_uniform_bending_rate_dissipates_as_the_rod(N):
    """On the CC manifold at rest length, bending rates dk_i (different per section) make the hinges
    dissipate sum c_j qdot_j^2 = sum_i eta_b_i d_i dk_i^2, the rod's Kelvin-Voigt power
    int eta_b (dkappa/dt)^2 ds for uniform curvature rates; with the q2 damping Dk of SlaveParams it
    adds Dk_i dk_i^2.  MuJoCo's own dof_damping is used."""
    slave = SlaveParams(bending_damping=(0.003, 0.002, 0.001))
    L0 = np.asarray(slave.rest_lengths)
    m, cm, c = _chain(N, slave)
    q2 = np.concatenate([L0, np.zeros(3)])
    dq2 = np.array([0.0, 0.0, 0.0, 0.7, -1.3, 2.1])
    qdot = cm.jacobian(q2) @ dq2
    power = float(np.sum(c * qdot**2))
    expected = float(np.sum((np.asarray(ETA_B) * L0 + np.asarray(slave.bending_damping)) * dq2[3:] ** 2))
    assert power == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("N", [1, 4, 8])
def test_uniform_extension_rate_dissipates_as_the_rod(N):
    """Equal extension viscosity and equal extension rates in every section (the boundary half rods
    in series then act like one rod): slides dissipate sum eta_a dd^2 / L0 (strain rate dd / L0 over
    the rest length L0), the rod's closed form."""
    slave = SlaveParams(rest_lengths=(0.3, 0.25, 0.2))
    L0 = np.asarray(slave.rest_lengths)
    eta_a = 0.4
    m, cm, c = _chain(N, slave, eta_a=(eta_a,) * 3)
    q2 = np.concatenate([L0, np.zeros(3)])
    r = 0.05
    dq2 = np.concatenate([r * L0, np.zeros(3)])  # the same strain rate r in every section
    qdot = cm.jacobian(q2) @ dq2
    power = float(np.sum(c * qdot**2))
    assert power == pytest.approx(float(np.sum(eta_a * (r * L0) ** 2 / L0)), rel=1e-12)


def test_damping_adds_to_the_slave_params_mapping():
    """Zero material damping gives exactly the old q2-damping mapping; the material part adds (per
    section: the boundary half rods put each section's total in series, additive when the sections'
    totals are equal, as here for the slides; hinges add per section)."""
    slave = SlaveParams(bending_damping=(0.01, 0.02, 0.03), extension_damping=(2.0, 2.0, 2.0))
    _, _, c_q2 = _chain(6, slave, (0.0,) * 3, (0.0,) * 3)
    _, _, c_mat = _chain(6, SlaveParams(), ETA_B, (0.3,) * 3)
    _, _, c_both = _chain(6, slave, ETA_B, (0.3,) * 3)
    np.testing.assert_allclose(c_both, c_q2 + c_mat, rtol=1e-12)
    assert np.all(c_mat > 0)


def test_fit_decay_recovers_a_damped_sinusoid():
    t = np.arange(1, 4001) * 1e-3
    f, z = 1.3, 0.012
    wn = 2 * np.pi * f / np.sqrt(1 - z**2)
    x = 0.2 + 0.05 * np.exp(-z * wn * t) * np.cos(2 * np.pi * f * t)
    fe, ze = fr.fit_decay(t, x, 0.2)
    assert fe == pytest.approx(f, rel=2e-4) and ze == pytest.approx(z, rel=1e-3)


@pytest.mark.slow
def test_small_motion_of_the_damped_chain_matches_the_rod():
    """Released 1 N tip deflection of the straight arm, default material damping on both: the free
    chain (N = 8) matches the Cosserat rod's first mode within 3 % in frequency and 10 % in damping
    ratio, and is closer to it than the CC-constrained chain and the analytic CC linearization
    (measured: rod 1.226 Hz / 0.0111, free 1.245 / 0.0120, CC chain 1.303 / 0.0118, CC 1.303 / 0.0127)."""
    rows = fr.modal_comparison(Ns=(8,), release_time=4.0, settle=2.0)
    by = {(r["model"], r["enforce_cc"]): r for r in rows}
    rod = by["Cosserat rod (reference)", False]
    free, cc = by["MuJoCo chain", False], by["MuJoCo chain", True]
    ana = by["analytic CC", True]
    assert free["f1_hz"] == pytest.approx(rod["f1_hz"], rel=0.03)
    assert free["zeta1"] == pytest.approx(rod["zeta1"], rel=0.10)
    assert abs(free["f1_hz"] - rod["f1_hz"]) < abs(cc["f1_hz"] - rod["f1_hz"])
    assert abs(free["f1_hz"] - rod["f1_hz"]) < abs(ana["f1_hz"] - rod["f1_hz"])
    # the analytic CC linearization and the CC chain agree with each other (same kinematics)
    assert cc["f1_hz"] == pytest.approx(ana["f1_hz"], rel=0.01)


def test_cc_static_is_an_equilibrium():
    slave = SlaveParams()
    q2c = fr.static_shapes(slave)["S"]
    q = fr.cc_static(slave, q2c, (1.0, 0.0))
    assert np.linalg.norm(fr.cc_gradient(slave, q, q2c, (1.0, 0.0))) < 1e-9
    assert np.linalg.norm(q - q2c) > 1e-3  # the loads do move it
    weightless = SlaveParams(gravity=(0.0, 0.0))
    np.testing.assert_allclose(fr.cc_static(weightless, q2c), q2c, atol=1e-12)


def test_worst_tip_error_by_optimization_beats_random_sampling():
    """N = 8: the optimizer finds the alternating +-max_bend, full-extension corner, 3.9 mm (4.34e-3 of
    sum(L0)), above the 50-random-sample maximum (2.47e-3)."""
    from harness.studies.fidelity import fidelity_study

    e, q = fr.worst_tip_error(8, n_random=8, n_refine=2)
    sampled = fidelity_study(Ns=(8,), n_samples=50, seed=0).errors["tip"][0]
    assert e > 1.5 * sampled
    assert e * 0.9e3 > 3.9
    np.testing.assert_allclose(q[:3], 0.45, rtol=1e-6)
    np.testing.assert_allclose(np.abs(q[3:] * q[:3]), np.pi / 2 * 0.45 / 0.45, rtol=1e-6)


def test_per_channel_noise_uses_each_signals_own_power():
    """add_noise_channel: std of channel i = RMS of its true signal x 10^(-SNR/20); a channel at zero
    gets none, a small channel gets proportionally small noise (unlike the per-vector model, where it
    gets the RMS of the whole mixed-unit vector)."""
    rng = np.random.default_rng(5)
    n, scale = 20000, 10 ** (-40 / 20)
    state = np.zeros(16)
    state[4:10] = [0.3, 0.3, 0.3, 1e-3, 2.0, -0.5]
    noise = np.concatenate([rng.standard_normal((n, 16)), np.zeros((n, 16))], axis=1)
    out = np.empty((n, 16))
    for k in range(n):
        kernels.add_noise_channel(state, noise, k, scale, out[k])
    std = (out - state).std(axis=0)
    np.testing.assert_allclose(std[4:10], np.abs(state[4:10]) * scale, rtol=0.03)
    assert np.all(std[state == 0] == 0)
    pv = np.empty(16)
    kernels.add_noise(state, noise[0], scale, pv)
    rms = np.sqrt(np.mean(state[4:10] ** 2))
    np.testing.assert_allclose((pv - state)[4:10], rms * scale * noise[0, 4:10], rtol=1e-12)


def test_noise_model_field_is_checked():
    assert load_scenario(None, ["noise_model=per_vector"]).noise_model == "per_vector"
    assert load_scenario(None).noise_model == "per_channel"
    with pytest.raises(ConfigError) as e:
        load_scenario(None, ["noise_model=gaussian"])
    assert "noise_model" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ConfigError) as e:
        load_scenario(None, ["plant.bending_viscosity=[0.01,-1,0.01]"])
    assert "plant.bending_viscosity" in str(e.value)


def test_stability_map_damping_stabilizes_torque_mode():
    """Free chain, torque mode, k_n = 100: diverges within 0.1 s at eta_b = 0.01 N m^2 s (default) and
    runs through 0.5 s at eta_b = 1 (README stability map)."""
    from harness.studies.stability_map import stability_map, stability_markdown

    rows = stability_map([100.0], [0.01, 1.0], ["plant.actuation=torque", "plant.enforce_cc=false"],
                         duration=0.5)
    by = {r["eta_b"]: r for r in rows}
    assert by[0.01]["status"] == "diverged" and by[0.01]["t_end"] < 0.1
    assert by[1.0]["status"] == "ok"
    assert "| 100 |" in stability_markdown(rows, 0.5)
