"""Invariants of the MJCF files and of the generated plant models (harness.plant.mujoco_model)."""

from __future__ import annotations

import re

import mujoco
import numpy as np
import pytest

from controllers.params import MasterParams, SlaveParams
from harness.config.errors import ConfigError
from harness.config.load import load_scenario
from harness.config.scenario import PlantConfig
from harness.plant import mujoco_model as pm
from harness.studies.fidelity import sample_q2, warning_count

MASTER = MasterParams()
SLAVE = SlaveParams()
NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
CASES = [(n, act, cc) for n in (1, 2, 4, 8) for act in ("servo", "torque") for cc in (False, True)]


def _model(n=4, actuation="servo", enforce_cc=False, **kw):
    plant = PlantConfig(segments=n, actuation=actuation, enforce_cc=enforce_cc, **kw)
    return pm.build_model(MASTER, SLAVE, plant)


def _named_objects(m: mujoco.MjModel):
    """(kind, index, name) of every body (but the world), joint, geom, site, actuator, equality, tendon."""
    for kind, count, getter in (
        ("body", m.nbody, m.body), ("joint", m.njnt, m.joint), ("geom", m.ngeom, m.geom),
        ("site", m.nsite, m.site), ("actuator", m.nu, m.actuator), ("equality", m.neq, m.equality),
        ("tendon", m.ntendon, m.tendon), ("light", m.nlight, m.light),
    ):
        for i in range(1 if kind == "body" else 0, count):
            yield kind, i, getter(i).name


def _step_1s(m, cm, load: bool):
    """Step 1 s; with load, apply the elastic correction and a mapped T2 through qfrc_applied at every
    step (servos aim at a bent shape)."""
    d = mujoco.MjData(m)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    idx = np.asarray(cm.chain_dof_adr)
    T2 = np.array([3.0, 2.0, 1.0, 0.2, -0.1, 0.05])
    if cm.actuation == "servo":
        d.ctrl[cm.chain_actuator_ids] = cm.joints_from_q2([0.33, 0.33, 0.33, 1.0, -1.0, 1.0])
    for _ in range(int(round(1.0 / m.opt.timestep))):
        if load:
            q = d.qpos[cm.chain_qpos_adr]
            d.qfrc_applied[idx] = cm.elastic_correction(q) + cm.force_from_T2(cm.q2_from_joints(q), T2)
        mujoco.mj_step(m, d)
    return d


# --- the hand-written files ------------------------------------------------------------------------

def test_master_xml_standalone_matches_defaults():
    m = mujoco.MjModel.from_xml_path(str(pm.MJCF_DIR / "master.xml"))
    assert m.njnt == 2 and m.nu == 2
    for name, (ln, ms) in zip(("master_upper_link", "master_fore_link"), zip(MASTER.lengths, MASTER.masses,
                                                                            strict=True), strict=True):
        b = m.body(name)
        assert b.mass[0] == ms
        np.testing.assert_allclose(b.ipos, [0, 0, ln / 2])
        assert b.inertia[1] == pytest.approx(ms * ln * ln / 12)
        i = np.sort(b.inertia)
        assert i[0] + i[1] >= i[2]  # triangle inequality
    np.testing.assert_allclose(m.body("master_base").pos, [0, -0.3, 0])
    for j in ("master_shoulder_joint", "master_elbow_joint"):
        np.testing.assert_allclose(m.joint(j).axis, [0, 1, 0])
    assert {m.actuator(i).name for i in range(m.nu)} == {"master_shoulder_motor", "master_elbow_motor"}
    # the MJCF defaults equal what build_model writes from MasterParams()
    mb, _ = _model(2)
    for name in ("master_upper_link", "master_fore_link"):
        np.testing.assert_allclose(mb.body(name).inertia, m.body(name).inertia, rtol=1e-15)
        np.testing.assert_allclose(mb.body(name).ipos, m.body(name).ipos, rtol=1e-15)


@pytest.mark.parametrize("path", ["master.xml", "octarm_base.xml", "scene.xml"])
def test_handwritten_files_step_without_warnings(path):
    m = mujoco.MjModel.from_xml_path(str(pm.MJCF_DIR / path))
    d = mujoco.MjData(m)
    if m.nu:
        d.ctrl[:] = [2.0, -1.0]
    for _ in range(1000):
        mujoco.mj_step(m, d)
    assert warning_count(d) == 0
    for kind, i, name in _named_objects(m):
        assert name and NAME_RE.match(name), (kind, i, name)


def test_build_spec_compiles_to_build_model():
    plant = PlantConfig(segments=3, enforce_cc=True)
    m1 = pm.build_spec(MASTER, SLAVE, plant).compile()
    m2, _ = pm.build_model(MASTER, SLAVE, plant)
    assert (m1.nq, m1.nu, m1.neq) == (m2.nq, m2.nu, m2.neq)
    np.testing.assert_array_equal(m1.actuator_gainprm, m2.actuator_gainprm)
    np.testing.assert_array_equal(m1.body_mass, m2.body_mass)


def test_stiffness_courant_number_default_is_explicitly_stable():
    """h w_max of the chain's joint springs (and servo kp) against the chain block of M at qpos0 (MuJoCo's
    own mj_fullM): explicit springs need < 2."""
    m, cm = _model(8, "torque")
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    idx = np.asarray(cm.chain_dof_adr)
    k = np.asarray(cm.joint_stiffness) + np.asarray(cm.servo_kp)
    Li = np.linalg.inv(np.linalg.cholesky(M[np.ix_(idx, idx)]))
    w2 = np.linalg.eigvalsh(Li @ (k[:, None] * Li.T))
    assert 0.0 < m.opt.timestep * np.sqrt(w2[-1]) < 2.0


def test_scene_options_and_bases():
    m = mujoco.MjModel.from_xml_path(str(pm.SCENE_XML))
    assert m.opt.timestep == 0.001
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    np.testing.assert_allclose(m.opt.gravity, [0, 0, -9.81])
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    # equality constraints only: no warm start, no island discovery (see scene.xml and the next test)
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_WARMSTART
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_ISLAND
    np.testing.assert_allclose(m.body("octarm_base").pos, [0, 0.3, 0])
    np.testing.assert_allclose(m.body("master_base").pos, [0, -0.3, 0])
    for path in ("master.xml", "octarm_base.xml"):
        text = (pm.MJCF_DIR / path).read_text()
        assert '<compiler angle="radian" autolimits="true"/>' in text


@pytest.mark.parametrize("actuation", ["servo", "torque"])
def test_cold_start_without_islands_solves_the_same_physics(actuation):
    """The scene turns warm-starting and island discovery off for speed: with only equality
    constraints the Newton problem is quadratic, so the closed-loop run's physics, replayed with both
    turned back on, reaches the same state (to rounding) and the solver needs one iteration."""
    from harness.config.scenario import Scenario
    from harness.loop.mujoco_loop import make_plant, simulate_mujoco

    scn = Scenario(duration=0.3, plant=PlantConfig(actuation=actuation, segments=4, enforce_cc=True))
    m, _, _ = make_plant(scn)
    log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
    assert simulate_mujoco(scn, cmd_log=log).status == "ok"
    ends = []
    for flags_on in (False, True):
        m, d, _ = make_plant(scn)
        if flags_on:
            D = mujoco.mjtDisableBit
            m.opt.disableflags &= ~int(D.mjDSBL_WARMSTART | D.mjDSBL_ISLAND)
        iters = 0
        for row in log:
            d.ctrl[:], d.qfrc_applied[:] = row[:m.nu], row[m.nu:]
            mujoco.mj_step(m, d)
            iters = max(iters, int(d.solver_niter[0]))
        assert d.nefc > 0 and iters == 1
        ends.append(np.concatenate([d.qpos, d.qvel]))
    np.testing.assert_allclose(ends[0], ends[1], rtol=0, atol=1e-12)


# --- generated models --------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("n,actuation,cc", CASES)
def test_model_compiles_steps_is_named_and_deterministic(n, actuation, cc):
    """Invariants of every generated model: compiles, every element named (snake_case), steps 1 s
    under load without a MuJoCo warning, and a second build steps to the same bits."""
    m, cm = _model(n, actuation, cc)
    assert cm.n_chain == 6 * n + 1 == m.nu - 2
    assert m.neq == (0 if not cc else 3 * (n - 1) + (1 if n == 1 else 3 * n - 2))
    names = list(_named_objects(m))
    for kind, i, name in names:
        assert name, f"unnamed {kind} {i}"
        assert NAME_RE.match(name), f"{kind} name {name!r} is not snake_case"
    # chain joints are consecutive, slide/hinge alternate, tip slide last
    assert np.all(np.diff(cm.chain_qpos_adr) == 1)
    assert m.joint(int(m.nq - 1)).name == "octarm_tip_slide"
    d = _step_1s(m, cm, load=True)
    assert warning_count(d) == 0
    assert np.all(np.isfinite(d.qpos))
    m2, cm2 = _model(n, actuation, cc)
    d2 = _step_1s(m2, cm2, load=True)
    assert d2.qpos.tobytes() == d.qpos.tobytes() and d2.qvel.tobytes() == d.qvel.tobytes()


def test_site_and_body_layout_on_manifold():
    """Body origins sit on the rest-length rods; straight chain at qpos0 has the rest length."""
    m, cm = _model(4)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(cm.octarm_tip(m, d), [0.0, sum(SLAVE.rest_lengths)], atol=1e-14)
    np.testing.assert_allclose(d.xpos[m.body("octarm_s0_seg0_body").id] - cm.octarm_base_pos,
                               [0, 0, SLAVE.rest_lengths[0] / 8], atol=1e-15)


def test_inertials_and_springs_follow_params():
    slave = SlaveParams(rest_lengths=(0.25, 0.3, 0.35), masses=(1.2, 0.6, 0.3),
                        bending_stiffness=(6.0, 2.0, 0.5), extension_stiffness=(900.0, 500.0, 300.0))
    N = 4
    m, cm = pm.build_model(MASTER, slave, PlantConfig(segments=N))
    chain_bodies = [m.body(f"octarm_s{i}_seg{j}_body").id for i in range(3) for j in range(N)]
    tip = m.body("octarm_tip_body").id
    assert m.body_mass[chain_bodies].sum() + m.body_mass[tip] == pytest.approx(sum(slave.masses), rel=1e-14)
    assert m.body_mass[tip] == pytest.approx(pm.TIP_MASS_FRACTION * slave.masses[2] / N)
    for c in range(cm.n_chain):
        jnt = m.joint(int(np.flatnonzero(m.jnt_qposadr == cm.chain_qpos_adr[c])[0]))
        assert jnt.stiffness[0] == cm.joint_stiffness[c]
        if cm.is_hinge[c]:
            i = cm.section[c]
            assert jnt.stiffness[0] == pytest.approx(N * slave.bending_stiffness[i] / slave.rest_lengths[i])
    # every body's inertia is valid (positive, triangle inequality)
    for b in np.flatnonzero(m.body_weldid != 0):  # moving bodies
        i = np.sort(m.body_inertia[b])
        assert i[0] > 0 and i[0] + i[1] >= i[2] * (1 - 1e-12)


def test_servo_gains_per_unit_length_of_the_section():
    """Each section's bend Theta_i, moved alone at the straight rest configuration (hinges Theta_i / N),
    is a servo of natural frequency f and damping ratio zeta against its inertia c^T M c (MuJoCo's M);
    the interior slides get N times the section-level extension gain (rods of length L0 / N)."""
    f, zeta = 15.0, 0.8
    for N in (3, 6):
        plant = PlantConfig(segments=N, actuation="servo", servo_frequency=f, servo_damping_ratio=zeta)
        m, cm = pm.build_model(MASTER, SLAVE, plant)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        dof = np.asarray(cm.chain_dof_adr)
        Mc = M[np.ix_(dof, dof)]
        w = 2 * np.pi * f
        ids = np.asarray(cm.chain_actuator_ids)
        kp = m.actuator_gainprm[ids, 0]
        np.testing.assert_allclose(m.actuator_biasprm[ids, 1], -kp, rtol=1e-12)
        kv = -m.actuator_biasprm[ids, 2]
        C = np.asarray(cm.C)
        for i in range(3):
            c = C[:, 3 + i]
            mu = c @ Mc @ c
            assert (c * kp) @ c == pytest.approx(mu * w * w, rel=1e-12)
            assert (c * kv) @ c == pytest.approx(2 * zeta * w * mu, rel=1e-12)
            ce = C[:, i]
            interior = (cm.section == i) & (cm.is_hinge == 0) & (cm.segment >= 1) & (cm.segment < N)
            np.testing.assert_allclose(kp[interior], N * (ce @ Mc @ ce) * w * w, rtol=1e-12)


def test_master_params_are_written():
    master = MasterParams(lengths=(0.5, 0.7), masses=(1.3, 0.8), damping=(0.1, 0.2))
    m, cm = pm.build_model(master, SLAVE, PlantConfig(segments=2))
    b = m.body("master_fore_link")
    np.testing.assert_allclose(b.pos, [0, 0, 0.5])
    assert b.mass[0] == 0.8 and b.inertia[1] == pytest.approx(0.8 * 0.49 / 12)
    np.testing.assert_allclose(m.site("master_tip_site").pos, [0, 0, 0.7])
    np.testing.assert_allclose(m.dof_damping[cm.master_dof_adr], [0.1, 0.2])


# --- maps ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [1, 2, 4, 8, 64])
def test_round_trip_and_virtual_work(n):
    layout = pm.chain_layout(n)
    np.testing.assert_allclose(layout["R"] @ layout["C"], np.eye(6), atol=1e-13)
    _, cm = _model(n, "torque")
    rng = np.random.default_rng(n)
    for q2 in sample_q2(SLAVE, 8, seed=n):
        q = cm.joints_from_q2(q2)
        np.testing.assert_allclose(cm.q2_from_joints(q), q2, rtol=1e-12, atol=1e-12)
        A = cm.jacobian(q2)
        dq2 = rng.standard_normal(6)
        np.testing.assert_allclose(cm.sense_joints(q, A @ dq2)[1], dq2, rtol=1e-12, atol=1e-11)
        # A is the derivative of joints_from_q2 (which is linear in [d - L0, k d])
        h = 1e-6
        A_fd = np.stack([(cm.joints_from_q2(q2 + h * e) - cm.joints_from_q2(q2 - h * e)) / (2 * h)
                         for e in np.eye(6)], axis=1)
        np.testing.assert_allclose(A, A_fd, atol=1e-9)
        T2 = rng.standard_normal(6) * np.array([10, 10, 10, 1, 1, 1])
        tau = cm.force_from_T2(q2, T2)
        np.testing.assert_allclose(A.T @ tau, T2, rtol=1e-12, atol=1e-12 * np.abs(T2).max())
        # same force on every joint of a kind within a section (interior slides, hinges)
        for i in range(3):
            h_sel = (cm.section == i) & (cm.is_hinge == 1)
            assert np.ptp(tau[h_sel]) <= 1e-12 * np.abs(tau[h_sel]).max()
            s_sel = (cm.section == i) & (cm.is_hinge == 0) & (cm.segment >= 1) & (cm.segment < n)
            if s_sel.any():
                assert np.ptp(tau[s_sel]) <= 1e-12 * np.abs(tau[s_sel]).max()
        # off the manifold the map is power-consistent with the sensing: tau . v = T2 . dq2_sensed
        qo = q + 1e-3 * rng.standard_normal(q.size)
        v = rng.standard_normal(q.size)
        q2o = cm.q2_from_joints(qo)
        assert cm.force_from_T2(q2o, T2) @ v == pytest.approx(T2 @ cm.sense_joints(qo, v)[1], rel=1e-10)


def _elastic_energy(cm, q) -> float:
    """The chain's elastic energy E (J) of which MuJoCo's springs plus `chain_elastic_correction` give
    -grad E: seg_kb_i / (2 d_i) sum_j theta_ij^2 + ke_i e_i^2 / 2 per section (d_i = L0_i + e_i,
    e = R[:3] q) plus k_shape r^2 / 2 on the slides, r = s - C_e e."""
    q = np.asarray(q, dtype=float)
    e = cm.R[:3] @ q
    hinge = cm.is_hinge == 1
    sq = np.bincount(cm.section[hinge], weights=q[hinge] ** 2, minlength=3)
    r = np.where(hinge, 0.0, q - cm.C[:, :3] @ e)
    return float(np.sum(0.5 * cm.seg_kb * sq / (cm.L0 + e) + 0.5 * cm.ke * e * e)
                 + np.sum(0.5 * cm.shape_stiffness * r * r))


def test_elastic_correction_is_gradient_of_energy():
    _, cm = _model(3)
    rng = np.random.default_rng(3)
    for q2 in sample_q2(SLAVE, 5, seed=7):
        q = cm.joints_from_q2(q2) + 2e-3 * rng.standard_normal(cm.n_chain)  # off the manifold
        f = cm.elastic_correction(q) - np.asarray(cm.joint_stiffness) * q  # = -grad E
        h = 1e-6
        g = np.array([(_elastic_energy(cm, q + h * e) - _elastic_energy(cm, q - h * e)) / (2 * h)
                      for e in np.eye(cm.n_chain)])
        np.testing.assert_allclose(-f, g, rtol=1e-6, atol=1e-6 * np.abs(g).max())
        # on the manifold the energy equals the analytic one
        qm = cm.joints_from_q2(q2)
        d, k = q2[:3], q2[3:]
        Kb, Ke, L0 = map(np.asarray, (SLAVE.bending_stiffness, SLAVE.extension_stiffness, SLAVE.rest_lengths))
        E_ref = np.sum(0.5 * Kb * d * k * k + 0.5 * Ke * (d - L0) ** 2)
        assert _elastic_energy(cm, qm) == pytest.approx(E_ref, rel=1e-13)


def test_mujoco_springs_are_linear_about_zero():
    m, cm = _model(2, "torque")
    d = mujoco.MjData(m)
    q2 = np.array([0.35, 0.4, 0.33, 2.0, -3.0, 2.5])
    cm.set_q2(d, q2)
    mujoco.mj_forward(m, d)
    idx = np.asarray(cm.chain_dof_adr)
    k = np.asarray(cm.joint_stiffness)
    np.testing.assert_allclose(d.qfrc_spring[idx], -k * cm.chain_qpos(d), rtol=1e-14)
    np.testing.assert_allclose(d.qfrc_passive[idx], d.qfrc_spring[idx], rtol=1e-14)


def test_kernels_compile_with_numba():
    """The maps compile in harness.loop.fast's shared namespace (numba, on-disk cache) and agree."""
    pytest.importorskip("numba")
    from harness.loop.fast import kernels

    jit = kernels(jit=True)
    _, cm = _model(2)
    q2 = np.array([0.35, 0.4, 0.33, 2.0, -3.0, 2.5])
    T2 = np.arange(1.0, 7.0)
    q = cm.joints_from_q2(q2) + 1e-3 * np.random.default_rng(0).standard_normal(cm.n_chain)
    v = np.linspace(-1, 1, cm.n_chain)
    n = cm.n_chain
    o = np.empty(n)
    jit.chain_joints_from_q2(q2, cm.C, cm.L0, o)
    np.testing.assert_array_equal(o, cm.joints_from_q2(q2))
    acc, scale = np.ones(n), np.linspace(0.5, 2.0, n)
    jit.chain_joints_rate_add(q2, T2, cm.C, scale, acc)  # T2 as a rate vector: any (6,) will do
    np.testing.assert_allclose(acc, 1.0 + scale * (cm.jacobian(q2) @ T2), rtol=1e-14, atol=1e-14)
    o6, p6 = np.empty(6), np.empty(6)
    jit.chain_sense(q, v, cm.R, cm.L0, p6, o6)
    np.testing.assert_array_equal(p6, cm.q2_from_joints(q))  # the same sums as the position-only map
    np.testing.assert_array_equal(o6, cm.sense_joints(q, v)[1])
    jit.chain_force_from_T2(q2, T2, cm.R, o)
    np.testing.assert_array_equal(o, cm.force_from_T2(q2, T2))
    jit.chain_elastic_correction(q, *cm.elastic_args, o)
    np.testing.assert_allclose(o, cm.elastic_correction(q), rtol=1e-14, atol=1e-12)


# --- determinism, export, errors ---------------------------------------------------------------------

def test_export_reloads(tmp_path):
    plant = PlantConfig(segments=3, enforce_cc=True)
    path = pm.export_mjcf(MASTER, SLAVE, plant, tmp_path / "plant_n3.xml")
    m2 = mujoco.MjModel.from_xml_path(str(path))
    m, cm = pm.build_model(MASTER, SLAVE, plant)
    assert (m2.nq, m2.nu, m2.neq, m2.ntendon, m2.nbody) == (m.nq, m.nu, m.neq, m.ntendon, m.nbody)
    d, d2 = mujoco.MjData(m), mujoco.MjData(m2)
    q2 = np.array([0.35, 0.4, 0.33, 2.0, -3.0, 2.5])
    cm.set_q2(d, q2)
    d2.qpos[:] = d.qpos
    mujoco.mj_kinematics(m, d)
    mujoco.mj_kinematics(m2, d2)
    # MuJoCo writes ~6 significant digits
    np.testing.assert_allclose(d2.site_xpos, d.site_xpos, atol=1e-6)


@pytest.mark.parametrize("bad", [0, 65, 2.5, True, "8", None])
def test_bad_segments(bad):
    """The plant options are checked once, by the scenario schema, before any model is built."""
    with pytest.raises(ConfigError, match=r"^plant\.segments = .*must be an integer in \[1, 64\]"):
        load_scenario({"plant": {"segments": bad}})


def test_bad_options():
    with pytest.raises(ConfigError, match=r"^plant\.actuation = 'pneumatic'"):
        load_scenario({"plant": {"actuation": "pneumatic"}})
    with pytest.raises(ConfigError, match=r"^plant\.integrator = 'leapfrog'"):
        load_scenario({"plant": {"integrator": "leapfrog"}})
    with pytest.raises(pm.PlantModelError, match="gravity"):
        pm.build_model(MasterParams(gravity=1.62), SLAVE, PlantConfig())


def test_missing_and_malformed_mjcf(tmp_path):
    missing = tmp_path / "nope.xml"
    with pytest.raises(pm.PlantModelError, match="nope.xml") as ei:
        pm.build_model(MASTER, SLAVE, PlantConfig(), scene_xml=missing)
    assert ei.value.__cause__ is None and ei.value.__context__ is None
    bad = tmp_path / "bad.xml"
    bad.write_text('<mujoco><worldbody><body name="x" pos="0 0 zz"/></worldbody></mujoco>')
    with pytest.raises(pm.PlantModelError, match="bad.xml") as ei:
        pm.build_model(MASTER, SLAVE, PlantConfig(), scene_xml=bad)
    assert "line" in str(ei.value).lower()  # MuJoCo's message is kept
    assert ei.value.__cause__ is None and ei.value.__suppress_context__  # no chained traceback
    # a scene whose include is missing names the include
    inc = tmp_path / "scene.xml"
    inc.write_text('<mujoco><include file="missing_robot.xml"/></mujoco>')
    with pytest.raises(pm.PlantModelError, match="missing_robot.xml"):
        pm.build_model(MASTER, SLAVE, PlantConfig(), scene_xml=inc)
    # a well-formed scene without the robots
    empty = tmp_path / "empty.xml"
    empty.write_text("<mujoco><worldbody/></mujoco>")
    with pytest.raises(pm.PlantModelError, match="empty.xml"):
        pm.build_model(MASTER, SLAVE, PlantConfig(), scene_xml=empty)
