"""The compiled fast paths give the same numbers as the plain Python ones (no timing assertions).

* recording geometry: `harness.loop.mujoco_kernels.kinematics_replay` (MuJoCo's C mj_kinematics called from
  numba) and `backbone_world` against a Python loop over `mujoco.mj_kinematics` / `slave.backbone`;
* the command log of `mujoco_chunk`: replaying the logged [ctrl, qfrc_applied] with raw mj_step from
  the same initial state reproduces the harness run's MuJoCo state bit for bit.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mujoco
import numpy as np
import pytest

from controllers import slave as slave_model
from harness.config.scenario import PlantConfig, Scenario
from harness.loop.fast import K
from harness.loop.mujoco_loop import BACKBONE_POINTS, chain_body_ids, make_plant, simulate_mujoco
from harness.loop.native import MJ_FUNCS


def _python_geometry(scn, m, cmap, qpos_hist, q2):
    """Reference: a plain Python loop over `mujoco.mj_kinematics` and `slave.backbone`, step by step."""
    n = qpos_hist.shape[0]
    d = mujoco.MjData(m)
    bodies = chain_body_ids(m, cmap)
    elbow = int(m.jnt_bodyid[m.joint("master_elbow_joint").id])
    body_pos = np.zeros((n, len(bodies), 3))
    body_quat = np.zeros((n, len(bodies), 4))
    master_pos = np.zeros((n, 3, 3))
    tip = np.zeros((n, 3))
    for k in range(n):
        d.qpos[:] = qpos_hist[k]
        mujoco.mj_kinematics(m, d)
        body_pos[k] = d.xpos[bodies]
        body_quat[k] = d.xquat[bodies]
        master_pos[k, 0] = d.xanchor[m.joint("master_shoulder_joint").id] if k == 0 else master_pos[0, 0]
        master_pos[k, 1] = d.xpos[elbow]
        master_pos[k, 2] = d.site_xpos[cmap.master_site_id]
        tip[k] = d.site_xpos[cmap.tip_site_id]
    base = np.asarray(cmap.octarm_base_pos)
    P = BACKBONE_POINTS
    bb = np.zeros((n, 3 * P + 1, 3))
    for k in range(n):
        pts = slave_model.backbone(scn.slave, q2[k], P)
        bb[k, :, 0] = base[0] + pts[:, 0]
        bb[k, :, 1] = base[1]
        bb[k, :, 2] = base[2] + pts[:, 1]
    x2 = np.stack([tip[:, 0] - base[0], tip[:, 2] - base[2]], axis=1)
    return body_pos, body_quat, master_pos, x2, bb


def _qpos_history(scn, cmd_log, n):
    """qpos at the start of each control step, rebuilt by replaying the command log in Python."""
    m, d, _ = make_plant(scn)
    qpos_hist = np.zeros((n, m.nq))
    for k in range(n):
        qpos_hist[k] = d.qpos
        for s in range(scn.substeps):
            row = cmd_log[k * scn.substeps + s]
            d.ctrl[:] = row[:m.nu]
            d.qfrc_applied[:] = row[m.nu:]
            mujoco.mj_step(m, d)
    return qpos_hist


@pytest.mark.parametrize("segments, integrator", [(2, "implicitfast"), (8, "implicitfast"), (2, "rk4"),
                                                  (4, "euler")])
def test_compiled_geometry_matches_python_replay(segments, integrator):
    """Geometry copied inside the loop (single-stage integrators) or replayed by the compiled
    mj_kinematics loop (RK4) = a plain Python mj_kinematics replay, bit for bit."""
    # the explicit integrators with torque actuation: they cannot integrate the servos' gains (docs/plants.md)
    act = "servo" if integrator == "implicitfast" else "torque"
    plant = PlantConfig(segments=segments, integrator=integrator, enforce_cc=True, actuation=act)
    scn = Scenario(duration=0.05, plant=plant)
    m, _, cmap = make_plant(scn)
    n = scn.n_steps
    cmd_log = np.zeros((n * scn.substeps, m.nu + m.nv))
    tr = simulate_mujoco(scn, cmd_log=cmd_log)
    assert tr.status == "ok" and len(tr) == n
    qpos_hist = _qpos_history(scn, cmd_log, n)
    body_pos, body_quat, master_pos, x2, bb = _python_geometry(scn, m, cmap, qpos_hist, tr.q2)
    np.testing.assert_array_equal(tr.body_pos, body_pos)
    np.testing.assert_array_equal(tr.body_quat, body_quat)
    np.testing.assert_array_equal(tr.master_pos, master_pos)
    np.testing.assert_array_equal(tr.x2_plant, x2)
    np.testing.assert_allclose(tr.meta["backbone"], bb, rtol=0, atol=1e-14)
    assert {"build_time", "wall_time", "geometry_time"} <= set(tr.meta)


def test_geometry_of_a_run_that_stops_early():
    """A run cut short by the controller (status != 0 after the record row, before stepping) still
    has the geometry of its last recorded step."""
    # the undamped free chain in torque mode stops within ms (README, stability map)
    undamped = {"bending_viscosity": (0.0,) * 3, "extension_viscosity": (0.0,) * 3}
    plant = PlantConfig(segments=8, enforce_cc=False, actuation="torque", **undamped)
    scn = Scenario(duration=1.0, plant=plant)
    m, _, cmap = make_plant(scn)
    cmd_log = np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv))
    tr = simulate_mujoco(scn, cmd_log=cmd_log)
    assert tr.status == "diverged" and 1 < len(tr) < scn.n_steps
    n = len(tr)
    qpos_hist = _qpos_history(scn, cmd_log, n)
    body_pos, body_quat, master_pos, x2, _ = _python_geometry(scn, m, cmap, qpos_hist, tr.q2)
    np.testing.assert_array_equal(tr.body_pos, body_pos)
    np.testing.assert_array_equal(tr.body_quat, body_quat)
    np.testing.assert_array_equal(tr.master_pos, master_pos)
    np.testing.assert_array_equal(tr.x2_plant, x2)


@pytest.mark.parametrize("actuation", ["servo", "torque"])
def test_command_log_replay_reproduces_the_run(actuation):
    """Raw mj_step with the logged commands from the same initial state = the harness's physics."""
    scn = Scenario(duration=0.1, plant=PlantConfig(actuation=actuation, segments=4))
    m, d, _ = make_plant(scn)
    n = scn.n_steps * scn.substeps
    log = np.zeros((n, m.nu + m.nv))
    tr = simulate_mujoco(scn, cmd_log=log)
    assert tr.status == "ok"
    assert np.any(log[:, m.nu:] != 0.0) and np.all(np.isfinite(log))
    qpos_end = np.zeros(m.nq)
    K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
    qpos_end[:] = d.qpos
    # the harness loop recorded q2 at the start of each control step: compare the last one
    m2, d2, cmap2 = make_plant(scn)
    for row in log[:-scn.substeps]:
        d2.ctrl[:] = row[:m2.nu]
        d2.qfrc_applied[:] = row[m2.nu:]
        mujoco.mj_step(m2, d2)
    np.testing.assert_array_equal(cmap2.sense(d2)[0], tr.q2[-1])
    for row in log[-scn.substeps:]:
        d2.ctrl[:] = row[:m2.nu]
        d2.qfrc_applied[:] = row[m2.nu:]
        mujoco.mj_step(m2, d2)
    np.testing.assert_array_equal(d2.qpos, qpos_end)


def test_command_log_off_by_default_and_checked():
    scn = Scenario(duration=0.01, plant=PlantConfig(segments=2))
    a = simulate_mujoco(scn)
    m, _, _ = make_plant(scn)
    b = simulate_mujoco(scn, cmd_log=np.zeros((scn.n_steps * scn.substeps, m.nu + m.nv)))
    np.testing.assert_array_equal(a.q2, b.q2)
    with pytest.raises(ValueError, match="cmd_log"):
        simulate_mujoco(dataclasses.replace(scn), cmd_log=np.zeros((3, 3)))


# ---------------------------------------------------------------------------------------------
# optimized controller kernels against their reference forms (tolerance 1e-12 relative)
# ---------------------------------------------------------------------------------------------
def _random_states(rng, n=25):
    q = np.column_stack([rng.uniform(0.3, 0.45, (n, 3)), rng.uniform(-4.0, 4.0, (n, 3))])
    q[0, 3:] = 0.0  # straight
    q[1, 3:] = 1e-9
    return q, rng.normal(size=(n, 6))


@pytest.mark.slow
@pytest.mark.parametrize("slice_inertia", [(0.0, 0.0, 0.0), (2e-3, 1e-3, 5e-4)])
def test_fused_mass_nle_equals_reference(slice_inertia):
    """mass_nle_kernel (moments of the quadrature, Lagrange-form Coriolis), compiled and interpreted, = the
    reference dynamics_kernel M2 and the Christoffel-form nle_kernel N2."""
    from controllers.params import SlaveParams
    from harness.loop.fast import kernels

    p = SlaveParams(slice_inertia=slice_inertia)
    pk = p.packed()
    nodes, weights = slave_model.gauss_legendre01(p.n_quad)
    q, dq = _random_states(np.random.default_rng(3))
    for Kx in (kernels(True), kernels(False)):
        _assert_mass_nle_matches_reference(Kx, pk, nodes, weights, q, dq)


def _assert_mass_nle_matches_reference(Kx, pk, nodes, weights, q, dq):
    """mass_nle_kernel's M2 and N2 = the reference dynamics_kernel's M2 and nle_kernel's N2 (Christoffel form,
    tests/reference_models.py) (1e-12) at each row of q, dq."""
    import reference_models as ref

    for a in range(len(q)):
        M, N = np.empty((6, 6)), np.empty(6)
        Kx.mass_nle_kernel(pk, q[a], dq[a], nodes, weights, M, N)
        Mr, G = np.empty((6, 6)), np.empty(6)
        ref.dynamics_kernel(pk, q[a], nodes, weights, False, Mr, np.empty((6, 6, 6)), G)
        Nr = np.empty(6)
        ref.nle_kernel(pk, q[a], dq[a], nodes, weights, np.empty((6, 6)), np.empty((6, 6, 6)),
                       np.empty((6, 6)), Nr)
        np.testing.assert_allclose(M, Mr, rtol=1e-12, atol=1e-12 * np.abs(Mr).max())
        np.testing.assert_allclose(N, Nr, rtol=1e-12, atol=1e-12 * np.abs(Nr).max())


def _node_sums(nodes, weights, th, f):
    """The moments of controllers.moments summed node by node (the reference)."""
    from controllers import cc

    R = np.zeros((3, 4), complex)
    for u, w in zip(nodes, weights, strict=True):
        b = cc.term_bases(u, th, f)
        R[0, 0] += w
        R[0, 1:] += [w * b[m] for m in range(3)]
        R[1, 1:] += [w * np.conj(b[0]) * b[m] for m in range(3)]
        R[2, 2:] += [w * np.conj(b[1]) * b[m] for m in (1, 2)]
    return R


@pytest.mark.parametrize("n", [2, 3, 8, 17, 32])
def test_section_moment_series_equal_the_node_sums(n):
    """controllers.moments: the power series in Theta give the quadrature's own sums (not the exact
    integrals: with 2 and 3 points these differ by 2.3e-3 and 3.4e-5 at |Theta| = 1.5), to 1e-15
    absolute over |Theta| <= MOMENT_RADIUS, compiled and interpreted; outside the radius, and for nodes
    that are not a tabulated rule, they decline (the kernel then sums node by node)."""
    from controllers import moments
    from harness.loop.fast import kernels

    nodes, weights = slave_model.gauss_legendre01(n)
    r = moments.MOMENT_RADIUS
    ths = np.concatenate([[0.0, 1e-300, -1e-9, r, -r, np.nextafter(r, 0.0)], np.linspace(-r, r, 61)])
    f = np.exp(0.7j)
    for Kx in (kernels(True), kernels(False)):
        for th in ths:
            Q = np.full((3, 4), np.nan, complex)
            assert Kx.section_moments(th, f, nodes, Q)
            R = _node_sums(nodes, weights, th, f)
            for k, m in [(0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3)]:
                assert abs(Q[k, m] - R[k, m]) <= 1e-15, (n, th, k, m, Q[k, m], R[k, m])
        Q = np.zeros((3, 4), complex)
        assert not Kx.section_moments(np.nextafter(r, 2.0), f, nodes, Q)
        assert not Kx.section_moments(-2.0 * r, f, nodes, Q)
        assert not Kx.section_moments(0.1, f, nodes[::-1].copy(), Q)  # not the tabulated rule
        assert not Kx.section_moments(0.1, f, np.array([0.5]), Q)  # 1 point: not tabulated
        assert not Kx.section_moments(0.1, f, slave_model.gauss_legendre01(33)[0], Q)
        assert not np.any(Q)
    if n == 2:  # the series is the 2-point rule's value, which is not the integral
        exact = _node_sums(*slave_model.gauss_legendre01(32), r, f)
        assert abs(_node_sums(nodes, weights, r, f) - exact).max() > 1e-4


@pytest.mark.parametrize("n_quad", [2, 8])
def test_fused_mass_nle_series_and_node_paths_agree(n_quad):
    """mass_nle_kernel on states whose sections all take the series (|Theta| <= 1.5), all take the node
    loop, or mix them, against the reference dynamics_kernel / nle_kernel (node by node), with 2 and 8
    points."""
    from controllers.params import SlaveParams
    from harness.loop.fast import kernels

    p = SlaveParams(n_quad=n_quad)
    pk = p.packed()
    nodes, weights = slave_model.gauss_legendre01(n_quad)
    rng = np.random.default_rng(5)
    d = rng.uniform(0.3, 0.45, (30, 3))
    outside = rng.uniform(1.5, 3.0, (10, 3)) * rng.choice([-1, 1], (10, 3))
    th = np.concatenate([rng.uniform(-1.5, 1.5, (10, 3)), outside, rng.uniform(-3.0, 3.0, (10, 3))])
    q = np.column_stack([d, th / d])
    dq = rng.normal(size=(30, 6))
    _assert_mass_nle_matches_reference(kernels(True), pk, nodes, weights, q, dq)


def test_tip_kinematics_equals_generic_chain_rule():
    """tip_kinematics (controllers.tip: closed forms by the tails, chain rule per pair of sections),
    compiled and interpreted, = the generic role-by-role path of tests/reference_models.py (point_y_derivs +
    chain_to_q + chain_to_q_dot), on random states, straight sections (k = 0), nearly straight ones and
    |k d| past E_n's series radius."""
    import reference_models as ref

    from controllers import cc, tip

    q, dq = _random_states(np.random.default_rng(4))
    rng = np.random.default_rng(41)
    d = rng.uniform(0.2, 0.5, (24, 3))
    k = rng.uniform(-12.0, 12.0, (24, 3)) * rng.choice([0.0, 1e-9, 0.01, 1.0], (24, 3))
    q = np.concatenate([q, np.column_stack([d, k])])
    dq = np.concatenate([dq, rng.normal(size=(24, 6))])
    assert np.abs(q[:, 3:] * q[:, :3]).max() > cc.SERIES_RADIUS and (q[:, 3:] == 0.0).any()
    for a in range(len(q)):
        c, Jq, Hq, Hqd = ref.tip_generic(q[a], dq[a])
        for fn in (K.tip_kinematics, tip.tip_kinematics):
            for order in (0, 1, 2, 3):
                x, J, H, Hd = np.zeros(2), np.zeros((2, 6)), np.zeros((2, 6, 6)), np.zeros((2, 6, 6))
                fn(q[a], dq[a], order, x, J, H, Hd)
                np.testing.assert_allclose(x, [c.imag, c.real], rtol=1e-14, atol=1e-15)
                if order >= 1:
                    np.testing.assert_allclose(J, np.stack([Jq.imag, Jq.real]), rtol=1e-13, atol=1e-14)
                if order >= 2:
                    ref_h = np.stack([Hq.imag, Hq.real])
                    np.testing.assert_allclose(H, ref_h, rtol=1e-12, atol=1e-13 * np.abs(ref_h).max())
                if order >= 3:
                    ref_h = np.stack([Hqd.imag, Hqd.real])
                    np.testing.assert_allclose(Hd, ref_h, rtol=1e-12, atol=1e-13 * np.abs(ref_h).max())


def test_en_tuple_equals_complex_series():
    """E_n by the real-arithmetic series (reciprocal table) = the complex power series."""
    from controllers.cc import SERIES_RADIUS, en_tuple

    for t in np.concatenate([np.linspace(-3.0, 3.0, 61), [1e-12, -1e-7, 1e-3, SERIES_RADIUS * 0.999]]):
        ref = np.zeros(4, complex)
        if abs(t) < SERIES_RADIUS:
            term = 1.0 + 0.0j
            for m in range(40):
                for n in range(4):
                    ref[n] += term / (n + m + 1)
                term = term * (1j * t) / (m + 1)
        else:
            e = np.exp(1j * t)
            ref[0] = (e - 1.0) / (1j * t)
            for n in range(1, 4):
                ref[n] = (e - n * ref[n - 1]) / (1j * t)
        np.testing.assert_allclose(np.array(en_tuple(t)), ref, rtol=1e-14, atol=1e-16)


@pytest.mark.parametrize("kind, cutoff", [("mujoco", None), ("analytic", None), ("analytic", 50.0)])
def test_noise_free_record_rows_equal_recomputed_rows(kind, cutoff):
    """Without noise the record row reuses the control laws' kinematics (record_row's info): the rows
    equal record_row recomputed from the true state, bit for bit; with the sensed-dq2 filter the laws see
    a filtered dq2, so the row is computed from the true state (de2 of the true dq2)."""
    import dataclasses

    from harness.loop import simulate
    from harness.loop.common import compile_model
    from harness.loop.trajectory import ROW_SLICES, ROW_WIDTH

    scn = Scenario(duration=0.2, snr_db=None, plant=PlantConfig(kind=kind, segments=4))
    scn = dataclasses.replace(scn, sensing=dataclasses.replace(scn.sensing, dq2_cutoff=cutoff))
    tr = simulate(scn)
    assert tr.status == "ok"
    a = compile_model(scn)
    row = np.zeros(ROW_WIDTH)
    xd, dxd, ddxd = np.empty(2), np.empty(2), np.empty(2)
    for k in range(0, len(tr), 7):
        state = np.concatenate([tr.q1[k], tr.dq1[k], tr.q2[k], tr.dq2[k]])
        K.desired(a.traj, tr.t[k], xd, dxd, ddxd)
        law = (tr.T1[k].copy(), tr.T2[k].copy(), tr.u2[k].copy(), tr.deN[k].copy(), np.empty(0), np.empty(0),
               xd, dxd, ddxd, np.empty(0))  # `loop_chunk`'s law: the laws' info and sensed unused
        K.record_row(tr.t[k], state, a, law, row, False)
        for name, sl in ROW_SLICES.items():
            got = np.atleast_1d(getattr(tr, name)[k])
            np.testing.assert_array_equal(got, row[sl], err_msg=f"{name} at step {k}")


@pytest.mark.parametrize("case", ["paper_delay", "contact"])
def test_chunk_boundaries_do_not_change_the_run(monkeypatch, case, traj_arrays):
    """The MuJoCo loop's compiled calls may split a run anywhere: one call, calls of 13 and of 97 steps
    and the default give bit-identical trajectories, with a command delay (its ring buffer spans the calls)
    and with contact and a delayed, filtered force sensor (scenarios/contact.toml)."""
    from harness.config.load import load_scenario
    from harness.loop import mujoco_loop

    root = Path(__file__).resolve().parents[1]
    short = ["duration=0.4", "transient=0", "plant.segments=4"]
    if case == "contact":
        scn = load_scenario(root / "scenarios" / "contact.toml", short)
    else:
        scn = load_scenario(root / "scenarios" / "paper.toml", [*short, "plant.actuation_delay=0.003"])
    runs = {}
    runs["default"] = traj_arrays(simulate_mujoco(scn))
    for size in (10 ** 9, 13, 97):
        monkeypatch.setattr(mujoco_loop, "MUJOCO_CHUNK", size)
        runs[f"calls of {size}"] = traj_arrays(simulate_mujoco(scn))
    ref = runs.pop("default")
    assert len(ref["t"]) == scn.n_steps and "body_pos" in ref
    if case == "contact":
        assert "contact_points" in ref and np.any(ref["F_true"] != 0.0)
    for name, arrays in runs.items():
        assert arrays.keys() == ref.keys(), name
        for key, v in arrays.items():
            np.testing.assert_array_equal(v, ref[key], err_msg=f"{name}: {key}")
