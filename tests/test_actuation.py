"""Actuation of the MuJoCo chain: the muscle groups (fixed tendons, force lag, one-sided limits), the
controller-side allocation kernel, servo gains per unit length, and the convergence in N of the static
hold and the first mode for every actuation (servo, torque, muscle).

References are independent of the production path: the CC fibre length d - s Theta in closed form,
the pair's 2x2 virtual-work matrix solved by numpy, MuJoCo's own tendon lengths, actuator forces and
transition Jacobians, and the static hold found by Newton on MuJoCo's generalized forces
(tests/actuation_statics.py)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from actuation_statics import Q2_HOLD, Hold, hold_T2, step_map_modes

from controllers.params import MasterParams, SlaveParams
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import PlantConfig
from harness.plant.chain_map import chain_layout, muscle_commands
from harness.plant.chain_params import servo_gains
from harness.plant.mujoco_model import build_model

SLAVE = SlaveParams()
RNG_Q2 = [np.array([0.32, 0.36, 0.41, 1.1, -2.0, 2.5]), np.array([0.30, 0.44, 0.33, -0.7, 0.4, -3.0])]


def _muscle_model(N: int, **plant):
    return build_model(MasterParams(), SLAVE, PlantConfig(segments=N, actuation="muscle", **plant))


def _coupled_fibre_jacobian(q2, r, N):
    """d l / d q2 (6, 6) of the chain's fibre lengths on the CC manifold (rows: groups in
    muscle_commands order), from the closed form l = d_i - s k_i d_i + (e_{i+-1} - e_i) / (4N) of the
    half-rod coefficients (chain_params.muscle_tendon_coefs)."""
    G = np.zeros((6, 6))
    for i in range(3):
        for g, s in enumerate((r[i], -r[i])):
            row = G[2 * i + g]
            row[i] = 1.0 - s * q2[3 + i]
            row[3 + i] = -s * q2[i]
            for nb in (i - 1, i + 1):
                if 0 <= nb < 3:
                    row[nb] += 1.0 / (4 * N)
                    row[i] -= 1.0 / (4 * N)
    return G


@pytest.mark.parametrize("N", [1, 4, 8])
def test_muscle_tendons_are_the_fibre_lengths(N):
    m, cm = _muscle_model(N)
    assert m.na == 6 and m.nu == 8 and cm.chain_actuator_ids.size == 0
    d0 = mujoco.MjData(m)
    mujoco.mj_forward(m, d0)
    d = mujoco.MjData(m)
    tid = m.actuator_trnid[cm.muscle_actuator_ids, 0]
    r = np.asarray(cm.muscle_radius)
    for q2 in RNG_Q2:
        cm.set_q2(d, q2)
        mujoco.mj_forward(m, d)
        e = q2[:3] - SLAVE.rest_lengths
        for i in range(3):
            for g, s in enumerate((r[i], -r[i])):
                ref = e[i] - s * q2[3 + i] * q2[i]
                ref += sum((e[nb] - e[i]) / (4 * N) for nb in (i - 1, i + 1) if 0 <= nb < 3)
                dl = d.ten_length[tid[2 * i + g]] - d0.ten_length[tid[2 * i + g]]
                assert dl == pytest.approx(ref, abs=1e-12)


def test_muscle_forces_map_by_virtual_work():
    """MuJoCo's actuator force through the tendons, mapped to q2 by A^T, equals G^T p with G the
    closed-form fibre Jacobian: T2 plus the stated O(1/N) half-rod coupling."""
    N = 8
    m, cm = _muscle_model(N)
    d = mujoco.MjData(m)
    for q2 in RNG_Q2:
        T2 = hold_T2(SLAVE, q2)
        p, _ = cm.muscle_commands(q2, T2)
        cm.set_q2(d, q2)
        d.act[:] = p  # unclipped, to test the map itself
        mujoco.mj_forward(m, d)
        Q = cm.jacobian(q2).T @ d.qfrc_actuator[cm.chain_dof_adr]
        G = _coupled_fibre_jacobian(q2, cm.muscle_radius, N)
        np.testing.assert_allclose(Q, G.T @ p, rtol=1e-10, atol=1e-9)
        # the k-rows are exact; the d-rows differ from T2 by the coupling only
        np.testing.assert_allclose(Q[3:], T2[3:], rtol=1e-10, atol=1e-9)
        G0 = _coupled_fibre_jacobian(q2, cm.muscle_radius, 1e300)  # the CC model's own fibres
        np.testing.assert_allclose(G0.T @ p, T2, rtol=1e-10, atol=1e-9)


def test_muscle_commands_solve_the_pair_and_count_saturation():
    rng = np.random.default_rng(3)
    r, fmax = np.array([0.16, 0.12, 0.09]), np.array([400.0, 300.0, 200.0])
    numba = pytest.importorskip("numba")
    jit = numba.njit(muscle_commands)
    for _ in range(20):
        q2 = np.concatenate([rng.uniform(0.3, 0.45, 3), rng.uniform(-4, 4, 3)])
        T2 = np.concatenate([rng.uniform(-50, 300, 3), rng.uniform(-20, 20, 3)])
        out, out_jit = np.empty(6), np.empty(6)
        n = muscle_commands(q2, T2, r, fmax, out)
        assert jit(q2, T2, r, fmax, out_jit) == n
        np.testing.assert_array_equal(out, out_jit)
        for i in range(3):
            d, k = q2[i], q2[3 + i]
            A = np.array([[1 - r[i] * k, 1 + r[i] * k], [-r[i] * d, r[i] * d]])
            np.testing.assert_allclose(out[2 * i:2 * i + 2], np.linalg.solve(A, [T2[i], T2[3 + i]]),
                                       rtol=1e-12, atol=1e-9)
        assert n == int(np.sum((out < 0) | (out > np.repeat(fmax, 2))))


def test_muscle_lag_and_one_sided_limits_are_mujocos():
    tau, fmax = (0.05, 0.03, 0.02), (400.0, 300.0, 200.0)
    m, cm = _muscle_model(4, muscle_time_constant=tau, muscle_max_force=fmax)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    ids = np.asarray(cm.muscle_actuator_ids)
    nx = 2 * m.nv + m.na
    A = np.zeros((nx, nx))
    B = np.zeros((nx, m.nu))
    mujoco.mjd_transitionFD(m, d, 1e-6, True, A, B, None, None)
    adr = 2 * m.nv + m.actuator_actadr[ids]
    dt = m.opt.timestep
    np.testing.assert_allclose(np.diag(A[np.ix_(adr, adr)]), np.exp(-dt / np.repeat(tau, 2)), rtol=1e-6)
    # commands beyond the range are clipped by MuJoCo: no pulling, no pushing past F_max
    d.ctrl[ids] = np.repeat(fmax, 2) * np.array([-1.0, 2.0, -1.0, 2.0, -1.0, 2.0])
    mujoco.mj_step(m, d)
    act = d.act[m.actuator_actadr[ids]]
    F = np.repeat(fmax, 2)
    np.testing.assert_allclose(act[0::2], 0.0, atol=0)
    np.testing.assert_allclose(act[1::2], F[1::2] * (1 - np.exp(-dt / np.repeat(tau, 2)[1::2])), rtol=1e-12)
    assert np.all(d.actuator_force[ids] >= 0.0)


def test_servo_gains_give_section_level_servos():
    """The N servos of a section in series are its section-level servo (C^T diag(kp) C on the bends
    is exactly mass_u w^2, whatever N)."""
    mass_u = np.array([2.0, 1.5, 0.8, 0.3, 0.1, 0.02])
    w = 2 * math.pi * 20.0
    for N in (1, 4, 16):
        lay = chain_layout(N)
        kp, kv = servo_gains(mass_u, N, lay, 20.0, 1.0)
        C = lay["C"]
        Ku = C.T @ (kp[:, None] * C)
        np.testing.assert_allclose(np.diag(Ku)[3:], mass_u[3:] * w * w, rtol=1e-12)
        np.testing.assert_allclose(kv, kp * 2.0 / w, rtol=1e-12)
        # equal sections extended uniformly: the slides in series (half rods at the boundaries) give
        # the section-level stiffness
        kp_eq, _ = servo_gains(np.r_[1.0, 1.0, 1.0, mass_u[3:]], N, lay, 20.0, 1.0)
        np.testing.assert_allclose((C.T @ (kp_eq[:, None] * C))[:3, :3].sum(), 3 * w * w, rtol=1e-12)


def test_muscle_fields_are_validated_in_one_line():
    for override, needle in (("plant.muscle_radius=[0.1,0,0.1]", "plant.muscle_radius"),
                             ("plant.muscle_time_constant=[0.05,0.05]", "plant.muscle_time_constant"),
                             ("plant.muscle_max_force=[1,2,-3]", "plant.muscle_max_force"),
                             ("plant.actuation=muscles", "plant.actuation")):
        with pytest.raises(ConfigError) as info:
            load_scenario(None, [override])
        assert str(info.value).startswith(needle) and "\n" not in str(info.value)


def test_hold_shape_is_within_the_muscle_range():
    """The convergence test's hold needs both groups of every section inside [0, F_max]."""
    out = np.empty(6)
    n = muscle_commands(Q2_HOLD, hold_T2(SLAVE, Q2_HOLD), np.array(PlantConfig().muscle_radius),
                        np.array(PlantConfig().muscle_max_force), out)
    assert n == 0, out


@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
def test_modes_agree_with_the_mj_step_map(actuation):
    """The slowest eigenvalue of the continuous linearization (the convergence test's first mode) and of
    MuJoCo's one-step map (log(mu) / dt) agree to the first-order integrator's O(|lambda| dt)."""
    h = Hold(4, actuation)
    h.solve()
    lc, ld = h.modes(), step_map_modes(h)
    a, b = lc[np.argmin(np.abs(lc))], ld[np.argmin(np.abs(ld))]
    dt = h.m.opt.timestep
    assert abs(b - a) <= 2 * abs(a) * (abs(a) * dt)
    assert np.max(lc.real) < 0 and np.max(ld.real) < 0  # the hold is stable


# ------------------------------------------------------------------------------------------------
# Convergence in N of the static hold (tip) and the first mode, per actuation
# ------------------------------------------------------------------------------------------------
TIP_TOL = 1e-3  # m: |tip(32) - extrapolated limit| (0.1 % of the arm's reach)
MODE_TOL = 5e-3  # relative: |f1(32) - extrapolated limit| / limit


def _series(actuation, Ns):
    tips, modes = [], []
    for N in Ns:
        h = Hold(N, actuation)
        if actuation == "muscle":
            assert h.n_sat == 0
        h.solve()
        tips.append(h.tip())
        modes.append(h.first_mode())
    return np.array(tips), np.array(modes)


def _orders(diffs):
    return np.log2(diffs[:-1] / diffs[1:])


@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
def test_hold_converges_fast_tier(actuation):
    """N = 4, 8, 16: the successive changes of the tip and the first mode shrink (at least first order)."""
    tips, modes = _series(actuation, (4, 8, 16))
    dt = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    dm = np.abs(np.diff(modes))
    assert _orders(dt)[0] >= 0.9, dt
    assert _orders(dm)[0] >= 0.9, dm


@pytest.mark.slow
@pytest.mark.parametrize("actuation", ["servo", "torque", "muscle"])
def test_hold_converges_in_N(actuation):
    """N = 4, 8, 16, 32: observed orders of the tip and the first mode at least 1 (0.9 allowing for the
    pre-asymptotic range), and N = 32 within TIP_TOL / MODE_TOL of the Richardson limit."""
    Ns = (4, 8, 16, 32)
    tips, modes = _series(actuation, Ns)
    dt = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    dm = np.abs(np.diff(modes))
    pt, pm = _orders(dt), _orders(dm)
    print(f"\n{actuation}: N {Ns}  tip X {tips[:, 0]}  Z {tips[:, 1]}  first mode (Hz) {modes}"
          f"  tip orders {pt}  mode orders {pm}")
    assert np.all(pt >= 0.9) and np.all(pm >= 0.9)
    p_t, p_m = min(pt[-1], 2.0), min(pm[-1], 2.0)  # extrapolate with the last observed order (<= 2)
    tip_lim = tips[-1] + (tips[-1] - tips[-2]) / (2 ** p_t - 1)
    mode_lim = modes[-1] + (modes[-1] - modes[-2]) / (2 ** p_m - 1)
    assert np.linalg.norm(tips[-1] - tip_lim) < TIP_TOL
    assert abs(modes[-1] - mode_lim) < MODE_TOL * abs(mode_lim)


def test_muscle_hold_by_stepping_mujoco():
    """mj_step with the elastic correction at every step (as the loop does): from zero muscle force the
    groups' forces rise as 1 - exp(-t / tau), and the arm settles onto the static hold found by Newton."""
    h = Hold(4, "muscle")
    h.solve()
    tip_eq = h.tip()
    m, cm = h.m, h.cm
    d = mujoco.MjData(m)
    cm.set_q2(d, Q2_HOLD)
    d.ctrl[:] = h.ctrl
    adr = m.actuator_actadr[cm.muscle_actuator_ids]
    tau = np.repeat(PlantConfig().muscle_time_constant, 2)
    dist = {}
    for k in range(1, int(round(6.0 / m.opt.timestep)) + 1):
        d.qfrc_applied[cm.chain_dof_adr] = cm.elastic_correction(cm.chain_qpos(d))
        mujoco.mj_step(m, d)
        if k == 50:
            np.testing.assert_allclose(d.act[adr] / h.ctrl[cm.muscle_actuator_ids],
                                       1 - np.exp(-50 * m.opt.timestep / tau), rtol=1e-9)
        if k in (1000, 3000, 6000):
            mujoco.mj_kinematics(m, d)
            dist[k] = np.linalg.norm(cm.octarm_tip(m, d) - tip_eq)
    assert dist[6000] < dist[3000] < dist[1000]
    assert dist[6000] < 2e-3


def test_muscle_plant_exports_and_reloads(tmp_path):
    from harness.plant.mujoco_model import export_mjcf

    path = export_mjcf(MasterParams(), SLAVE, PlantConfig(segments=3, actuation="muscle"), tmp_path / "m.xml")
    m = mujoco.MjModel.from_xml_path(str(path))
    assert m.ntendon == 6 and m.na == 6
    ids = [m.actuator(f"octarm_s{i}_muscle_{t}").id for i in range(3) for t in ("pos", "neg")]
    np.testing.assert_allclose(m.actuator_ctrlrange[ids, 0], 0.0)
    np.testing.assert_allclose(m.actuator_ctrlrange[ids, 1], np.repeat(PlantConfig().muscle_max_force, 2))
    assert np.all(m.actuator_dyntype[ids] == mujoco.mjtDyn.mjDYN_FILTEREXACT)
