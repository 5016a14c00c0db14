"""Analytic models against independent references: finite differences, energies, identities."""

import numpy as np
import pytest
import reference_models as ref

from controllers import master, slave, subtasks
from controllers.params import MasterParams, ParameterError, SlaveParams, SubtaskSpec
from harness.loop.fast import kernels

SP = SlaveParams(slice_inertia=(2e-3, 1e-3, 5e-4), extension_damping=(1.0, 2.0, 3.0),
                 bending_damping=(0.1, 0.2, 0.3))
MP = MasterParams(damping=(0.2, 0.1))
H = 1e-6


def random_q2(rng, p=SP, n=5):
    lo, hi = p.length_range
    out = []
    for _ in range(n):
        d = rng.uniform(lo, hi)
        th = rng.uniform(-p.max_bend, p.max_bend, 3)
        out.append(np.concatenate([d, th / d]))
    return out


def fd(f, q, h=H):
    """Central difference of f at q along each coordinate; result stacks on the last axis."""
    return np.stack([(f(q + h * e) - f(q - h * e)) / (2 * h) for e in np.eye(len(q))], axis=-1)


@pytest.fixture(scope="module")
def rng():
    return np.random.default_rng(1234)


def test_slave_jacobian_hessian_and_rates_against_finite_differences(rng):
    for q in random_q2(rng):
        dq = rng.normal(size=6)
        x, J, Hs, Hd = slave.tip_derivatives(SP, q, dq)
        np.testing.assert_allclose(J, fd(lambda z: slave.tip_position(SP, z), q), atol=1e-8)
        np.testing.assert_allclose(Hs, fd(lambda z: slave.jacobian(SP, z), q), atol=1e-7)
        Jd_fd = (slave.jacobian(SP, q + H * dq) - slave.jacobian(SP, q - H * dq)) / (2 * H)
        np.testing.assert_allclose(slave.jacobian_dot(SP, q, dq), Jd_fd, atol=1e-7)
        Hd_fd = (slave.tip_hessian(SP, q + H * dq) - slave.tip_hessian(SP, q - H * dq)) / (2 * H)
        np.testing.assert_allclose(Hd, Hd_fd, atol=1e-6)


def test_slave_tip_matches_closed_form_arc_sum(rng):
    for q in random_q2(rng):
        c, phi = 0j, 0.0
        for i in range(3):
            d, k = q[i], q[3 + i]
            c += np.exp(1j * phi) * (np.exp(1j * k * d) - 1) / (1j * k)
            phi += k * d
        np.testing.assert_allclose(slave.tip_position(SP, q), [c.imag, c.real], atol=1e-14)
        pts = slave.backbone(SP, q, 7)
        np.testing.assert_allclose(pts[-1], [c.imag, c.real], atol=1e-14)


def test_slave_mass_matrix_spd_and_derivative(rng):
    """Production M2 symmetric positive definite; the reference's exact dM2/dq2 = finite differences of it."""
    for q in random_q2(rng, n=3):
        M = slave.mass_matrix(SP, q)
        np.testing.assert_allclose(M, M.T, atol=0)
        assert np.linalg.eigvalsh(M).min() > 0
        dM = ref.mass_matrix_derivative(SP, q)
        np.testing.assert_allclose(dM, fd(lambda z: slave.mass_matrix(SP, z), q), atol=1e-7)


def test_coriolis_skew_symmetry_and_lagrange_form(rng):
    """Reference: dM/dt - 2C skew-symmetric (C from the Christoffel symbols).  Production: the velocity part
    of N2, N2(q, dq) - N2(q, 0) - D dq, equals dM/dt dq - dT/dq (Lagrange's equations, T = dq^T M2 dq / 2
    with M2 the production mass matrix differentiated by finite differences) and the reference's C dq."""
    D = np.concatenate([SP.extension_damping, SP.bending_damping])
    for q in random_q2(rng, n=3):
        dq = rng.normal(size=6)
        C = ref.coriolis_matrix(SP, q, dq)
        Md = ref.mass_matrix_derivative(SP, q) @ dq
        S = Md - 2 * C
        np.testing.assert_allclose(S, -S.T, atol=1e-12)

        def T(qq, vv):
            return 0.5 * vv @ slave.mass_matrix(SP, qq) @ vv
        dTdq = fd(lambda z: np.array(T(z, dq)), q)
        Md_fd = (slave.mass_matrix(SP, q + H * dq) - slave.mass_matrix(SP, q - H * dq)) / (2 * H)
        cor = slave.nle(SP, q, dq) - slave.nle(SP, q, np.zeros(6)) - D * dq
        np.testing.assert_allclose(cor, Md_fd @ dq - dTdq, atol=1e-7)
        np.testing.assert_allclose(cor, C @ dq, rtol=1e-11, atol=1e-11 * np.abs(C @ dq).max())


def _potential(p, q):
    """Gravity + elastic potential by independent quadrature over backbone points."""
    n = 400  # midpoint rule per section, independent of the model's Gauss-Legendre code
    V = 0.0
    g = np.asarray(p.gravity)
    for s in range(3):
        # material midpoints of section s: evaluate the arc point directly
        for u in (np.arange(n) + 0.5) / n:
            c, phi = 0j, 0.0
            for j in range(s + 1):
                d, k = q[j], q[3 + j]
                ll = d * (u if j == s else 1.0)
                c += np.exp(1j * phi) * (np.exp(1j * k * ll) - 1) / (1j * k)
                phi += k * d
            V -= p.masses[s] / n * (g[0] * c.imag + g[1] * c.real)
    d, k = q[:3], q[3:]
    Ve = np.sum(0.5 * np.array(p.bending_stiffness) * d * k**2
                + 0.5 * np.array(p.extension_stiffness) * (d - np.array(p.rest_lengths)) ** 2)
    return V, Ve


def test_gravity_and_elastic_forces_are_potential_gradients(rng):
    for q in random_q2(rng, n=2):
        G = fd(lambda z: np.array(_potential(SP, z)[0]), q, h=1e-5)
        np.testing.assert_allclose(slave.gravity_force(SP, q), G, rtol=1e-4, atol=1e-5)
        E = fd(lambda z: np.array(_potential(SP, z)[1]), q)
        np.testing.assert_allclose(slave.elastic_force(SP, q), E, atol=1e-6)


def test_straight_arm_is_finite_and_continuous():
    """All curvatures exactly 0: every quantity is finite, and it is smooth across k = 0: the one-sided
    difference quotients along a curvature direction agree (they differ by e f'' ~ 1e-6 here; a jump
    or a kink at k = 0 would make them differ by O(1))."""
    q0 = np.array([0.3, 0.32, 0.35, 0.0, 0.0, 0.0])
    dq = np.array([0.1, -0.2, 0.3, 0.5, -0.4, 0.2])
    fs = {"tip": lambda q: slave.tip_position(SP, q), "J2": lambda q: slave.jacobian(SP, q),
          "H": lambda q: slave.tip_hessian(SP, q), "dH/dt": lambda q: slave.tip_derivatives(SP, q, dq)[3],
          "M2": lambda q: slave.mass_matrix(SP, q), "dM2/dq": lambda q: ref.mass_matrix_derivative(SP, q),
          "N2": lambda q: slave.nle(SP, q, dq),
          "grad beta": lambda q: subtasks.beta(SubtaskSpec(), SP, q, dq)[1],
          "d/dt grad beta": lambda q: subtasks.beta(SubtaskSpec(), SP, q, dq)[2]}
    v = np.r_[0, 0, 0, 1.0, -1.0, 1.0]
    e = 1e-6
    for name, f in fs.items():
        f0 = f(q0)
        assert np.all(np.isfinite(f0)), name
        right, left = (f(q0 + e * v) - f0) / e, (f0 - f(q0 - e * v)) / e
        scale = max(np.abs(right).max(), 1.0)
        assert np.abs(right - left).max() / scale < 1e-4, name
    # straight extensible arm: Z = sum d, X = 0, and J2 has full rank (not a singularity)
    np.testing.assert_allclose(slave.tip_position(SP, q0), [0.0, q0[:3].sum()], atol=1e-15)
    assert subtasks.manipulability(SP, q0) > 0.1


def test_series_and_closed_form_branches_agree():
    """E_n switches from its power series to the recursion at |t| = 2: both sides agree."""
    from controllers.cc import SERIES_RADIUS, en_tuple

    for t in (SERIES_RADIUS * (1 - 1e-12), -SERIES_RADIUS * (1 - 1e-12)):
        a, b = np.array(en_tuple(t)), np.array(en_tuple(t * (1 + 2e-12)))
        np.testing.assert_allclose(a, b, atol=1e-12)
    for t in (0.3, 1.7, 2.5, 3.1):
        a = np.array(en_tuple(t))
        v = (np.arange(200000) + 0.5) / 200000
        for n in range(4):
            np.testing.assert_allclose(a[n], np.mean(v**n * np.exp(1j * t * v)), atol=1e-10)


def test_subtask_gradient_and_rate_against_finite_differences(rng):
    spec = SubtaskSpec(kinds=("manipulability", "limits"), weights=(1.0, 0.3))
    for q in random_q2(rng, n=4):
        dq = rng.normal(size=6)
        b, grad, graddot = subtasks.beta(spec, SP, q, dq)
        np.testing.assert_allclose(grad, fd(lambda z: np.array(subtasks.beta(spec, SP, z)[0]), q),
                                   atol=1e-7)
        gd_fd = (subtasks.beta(spec, SP, q + H * dq)[1] - subtasks.beta(spec, SP, q - H * dq)[1]) / (2 * H)
        np.testing.assert_allclose(graddot, gd_fd, atol=1e-6)
        assert b == pytest.approx(np.sqrt(np.linalg.det(slave.jacobian(SP, q) @ slave.jacobian(SP, q).T))
                                  + 0.3 * subtasks.limits_kernel(
                                      subtasks.pack_subtask(spec, SP), q, dq, np.empty(6), np.empty(6)))
        # J_s and g of (31), (33), and dg/dt against finite differences
        ya, Js, g, gd = ref.null_space_reference(spec, SP, 1.0, 1.0, q, dq)
        np.testing.assert_allclose(Js, fd(lambda z: np.array(np.exp(-subtasks.beta(spec, SP, z)[0])), q),
                                   atol=1e-8)
        g_fd = (ref.null_space_reference(spec, SP, 1.0, 1.0, q + H * dq, dq)[2]
                - ref.null_space_reference(spec, SP, 1.0, 1.0, q - H * dq, dq)[2]) / (2 * H)
        np.testing.assert_allclose(gd, g_fd, atol=1e-6)


def test_moore_penrose_identities_and_null_space(rng):
    """(8), (9), (10), J2 phi_N = 0 (22) and the exact dJ2^+/dt, to 1e-10."""
    from controllers.control import slave_control
    from controllers.params import Gains

    for q in random_q2(rng):
        dq = rng.normal(size=6)
        J = slave.jacobian(SP, q)
        g, dg = rng.normal(size=6), rng.normal(size=6)
        Jp, Jpd, P, Jphi, deN = ref.null_space_quantities(SP, q, dq, g, dg)
        np.testing.assert_allclose(J @ Jp, np.eye(2), atol=1e-10)  # (8)
        np.testing.assert_allclose(P @ P, P, atol=1e-10)  # (9)
        np.testing.assert_allclose(P @ Jp, 0, atol=1e-10)  # (10)
        np.testing.assert_allclose(J @ Jphi, 0, atol=1e-10)
        phiN = P @ (dg + 100 * deN) - Jphi @ (g - dq)  # (27)
        np.testing.assert_allclose(J @ phiN, 0, atol=1e-10)  # (22)
        Jp_fd = (ref.null_space_quantities(SP, q + H * dq, dq, g, dg)[0]
                 - ref.null_space_quantities(SP, q - H * dq, dq, g, dg)[0]) / (2 * H)
        np.testing.assert_allclose(Jpd, Jp_fd, atol=1e-7)
        # dP/dt = -(dJ^+ J + J^+ dJ) (behind (24)-(26)), against central differences of P itself
        P_fd = (ref.null_space_quantities(SP, q + H * dq, dq, g, dg)[2]
                - ref.null_space_quantities(SP, q - H * dq, dq, g, dg)[2]) / (2 * H)
        np.testing.assert_allclose(-(Jpd @ J + Jp @ slave.jacobian_dot(SP, q, dq)), P_fd, atol=1e-7)
        # the full law: u2 satisfies J2 u2 = commanded task acceleration - dJ2 dq2
        out = slave_control(SP, Gains(), SubtaskSpec(), q, dq, np.array([0.05, 1.0]), np.zeros(2),
                            np.array([0.1, -0.2]))
        v = np.array([0.1, -0.2]) + 10 * out["de2"] + 15 * out["e2"] - slave.jacobian_dot(SP, q, dq) @ dq
        np.testing.assert_allclose(J @ out["u2"], v, atol=1e-10)


def test_master_model_against_finite_differences_and_energy(rng):
    for _ in range(5):
        q, dq = rng.uniform(-2, 2, 2), rng.normal(size=2)
        np.testing.assert_allclose(master.jacobian(MP, q), fd(lambda z: master.fk(MP, z), q), atol=1e-9)
        Jd = (master.jacobian(MP, q + H * dq) - master.jacobian(MP, q - H * dq)) / (2 * H)
        np.testing.assert_allclose(master.jacobian_dot(MP, q, dq), Jd, atol=1e-8)
        # Lagrange: N1 = dM/dt dq - dT/dq + dV/dq + B dq with T = dq^T M dq / 2
        Md = (master.mass_matrix(MP, q + H * dq) - master.mass_matrix(MP, q - H * dq)) / (2 * H)
        dTdq = fd(lambda z: np.array(0.5 * dq @ master.mass_matrix(MP, z) @ dq), q)
        l1, l2 = MP.lengths
        m1, m2 = MP.masses

        def V(z):
            return MP.gravity * (m1 * l1 / 2 * np.cos(z[0])
                                 + m2 * (l1 * np.cos(z[0]) + l2 / 2 * np.cos(z[0] + z[1])))

        expected = Md @ dq - dTdq + fd(lambda z: np.array(V(z)), q) + np.array(MP.damping) * dq
        np.testing.assert_allclose(master.nle(MP, q, dq), expected, atol=1e-7)
        qi = master.ik(MP, master.fk(MP, q), elbow=int(np.sign(q[1])))
        np.testing.assert_allclose(master.fk(MP, qi), master.fk(MP, q), atol=1e-12)


def test_compiled_kernels_equal_interpreted(rng):
    """harness.loop.fast compiles controllers/ unchanged: same numbers as the interpreted code."""
    Kj, Kp = kernels(True), kernels(False)
    nodes, weights = slave.gauss_legendre01(8)
    spec = subtasks.pack_subtask(SubtaskSpec(), SP)
    for q in random_q2(rng, n=2):
        dq = rng.normal(size=6)
        outs = []
        for Kx in (Kj, Kp):
            T2, u2, deN, info = np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(11)
            Kx.slave_control_kernel(SP.packed(), nodes, weights, np.array([3, 10, 10, 15, 1, 1, 100.0]), spec,
                                    q, dq, np.array([0.05, 1.0]), np.zeros(2), np.zeros(2), np.zeros(2),
                                    T2, u2, deN, info)
            outs.append(np.concatenate([T2, u2, deN, info]))
        np.testing.assert_allclose(outs[0], outs[1], rtol=1e-12, atol=1e-12)


def test_fused_loop_dynamics_equal_christoffel_form(rng):
    """The production kernel (Lagrange-form Coriolis, moments of the quadrature) equals M2, G2 and the
    Christoffel-symbol N2 of the reference implementation (tests/reference_models.py)."""
    for q in random_q2(rng, n=4):
        dq = rng.normal(size=6)
        M, N = slave.mass_and_nle(SP, q, dq)
        np.testing.assert_allclose(M, ref.mass_matrix(SP, q), rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(N, ref.nle(SP, q, dq), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(slave.gravity_force(SP, q), ref.gravity_force(SP, q),
                                   rtol=1e-12, atol=1e-12)


def test_controllers_import_numpy_only():
    """controllers/ (analytic models and control laws) imports numpy and nothing of the harness side:
    checked in a fresh interpreter after importing every module of the package."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    mods = sorted(p.stem for p in (root / "controllers").glob("*.py") if p.stem != "__init__")
    code = ("import importlib, sys\n"
            f"for m in {mods!r}: importlib.import_module('controllers.' + m)\n"
            "bad = sorted({n.split('.')[0] for n in sys.modules}\n"
            "             & {'mujoco', 'rerun', 'matplotlib', 'numba', 'harness', 'scipy', 'pyarrow'})\n"
            "print(','.join(bad))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"controllers/ pulls in {res.stdout.strip()}"
    assert len(mods) >= 6


@pytest.mark.parametrize("make, text", [
    (lambda: SlaveParams(gravity=(0.0, 0.0, -9.81)), "SlaveParams.gravity = (0.0, 0.0, -9.81): must have 2"),
    (lambda: SlaveParams(rest_lengths=(0.3, 0.3)), "SlaveParams.rest_lengths = (0.3, 0.3): must have 3"),
    (lambda: MasterParams(lengths=(0.6, 0.6, 0.6)), "MasterParams.lengths = (0.6, 0.6, 0.6): must have 2"),
    (lambda: SubtaskSpec(kinds=("manipulabilty",), weights=(1.0,)), "subtask.kinds = ('manipulabilty',)"),
    (lambda: SubtaskSpec(kinds=("limits", "limits"), weights=(1.0, 1.0)),
     "subtask.kinds = ('limits', 'limits')"),
])
def test_parameters_built_in_python_refuse_a_layout_they_cannot_pack(make, text):
    """The packed layout of the kernels needs each field's size; an unknown sub-task kind would silently
    switch the null-space task off: both are one-line ParameterErrors, also outside a scenario file."""
    with pytest.raises(ParameterError) as e:
        make()
    assert str(e.value).startswith(text) and "\n" not in str(e.value)
