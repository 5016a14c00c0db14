"""Linear stability of the sampled-data closed loop (harness.studies.stability, `teleop stability`).

Known answer: on the analytic plant under the paper's law without noise the error dynamics are (15) and
(21), double integrators closed by PD laws; under a zero-order hold of the torque over T the sampled
double integrator e'' = -kd e' - kp e (held) has the one-period matrix

    [[1 - kp T^2 / 2, T - kd T^2 / 2], [-kp T, 1 - kd T]],

(an independent closed form written here, not in production) and the null-space velocity, driven by
-kn dq2_N held over T, decays by 1 - kn T per period.  The plant is nonlinear: during the hold M(q) and the
gravity / elastic forces move with q, which the law cancels only at the sample; the linearized
residual is an extra acceleration ~ (M^-1 dN/dq) (q(t) - q_k) = O(w^2 T) with w^2 the stiffest
M^-1 dN/dq of the arm (Ke_i / m_i = 1000 s^-2 here), so the eigenvalues of the one-period map differ
from the closed forms by O(w^2 T^2 / 2) (5e-4 at 1 ms).  At a fixed target (no motion of the operating
point during the hold) the test checks that bound and that the difference falls as T^2 (at least by 3x
when T is halved).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from harness.config.load import load_scenario
from harness.studies.stability import linearize

FIXED_TARGET = ["plant.kind=analytic", "snr_db=none", "trajectory.amplitude=[0.0,0.0]"]


def zoh_double_integrator(kd: float, kp: float, T: float) -> np.ndarray:
    A = np.array([[1 - kp * T**2 / 2, T - kd * T**2 / 2], [-kp * T, 1 - kd * T]])
    return np.linalg.eigvals(A)


def _match(ev: list, predicted: list) -> list[float]:
    """Greedy nearest matching of predicted poles to measured ones (each measured used once)."""
    ev = list(ev)
    errs = []
    for p in predicted:
        j = int(np.argmin([abs(e - p) for e in ev]))
        errs.append(abs(ev[j] - p))
        ev.pop(j)
    return errs


def _known_answer(T: float):
    scn = load_scenario(None, [*FIXED_TARGET, f"control_dt={T}", f"plant.physics_dt={T}"])
    res = linearize(scn, 2.0)
    g = scn.gains
    e1 = list(zoh_double_integrator(g.k1, g.k2, T)) * 2  # e1 = [X, Z] of the master tip, eq. (15)
    e2 = list(zoh_double_integrator(g.k3, g.k4, T)) * 2  # e2, eq. (21)
    return res, scn, _match(res.eigenvalues, e1), _match(res.eigenvalues, e2)


@pytest.fixture(scope="module")
def known():
    return {T: _known_answer(T) for T in (1e-3, 5e-4)}


def test_error_poles_match_zoh_closed_forms_and_converge_as_T_squared(known):
    (_, scn, e1a, e2a), (_, _, e1b, e2b) = known[1e-3], known[5e-4]
    w2 = max(np.asarray(scn.slave.extension_stiffness) / np.asarray(scn.slave.masses))
    T = 1e-3
    bound = w2 * T**2 / 2
    assert max(e1a + e2a) < bound, (e1a, e2a, bound)
    # second order in T: halving T divides the largest mismatch by > 3 (exactly 4 for a pure T^2 term)
    assert max(e1b) < max(e1a) / 3, (e1a, e1b)
    assert max(e2b) < max(e2a) / 3, (e2a, e2b)
    # and the poles are those of (15)/(21), not merely near 1: each within a small fraction of 1 - |lambda|
    for err, lam in zip(e1a, zoh_double_integrator(scn.gains.k1, scn.gains.k2, T).tolist() * 2, strict=True):
        assert err < 0.05 * (1 - abs(lam))


def test_null_space_velocity_modes_decay_as_one_minus_kn_T(known):
    for T, (res, scn, _, _) in known.items():
        kn = scn.gains.kn
        order = np.argsort(np.abs(res.eigenvalues - (1 - kn * T)))
        near, others = res.eigenvalues[order[:4]], res.eigenvalues[order[4:]]
        rates = [(1 - e.real) / T for e in near]
        assert all(abs(e.imag) < 1e-9 for e in near)
        # the four null-space velocity modes (6 slave dofs - 2 task dofs) decay at k_n within 10 %
        assert all(abs(r - kn) < 0.1 * kn for r in rates), (T, rates)
        # nothing else is that fast: the next mode is slower than k_n / 5
        assert min(abs(e) for e in others) > 1 - kn * T / 5


def test_torque_free_chain_flips_at_nyquist_and_cc_chain_does_not():
    """The measured finding: at k_n = 100 (t = 1 s) the free chain in torque actuation has a real negative
    eigenvalue beyond -1 (a flip every control period, 1 / (2 T) = 500 Hz) on the hinges of the section 0/1
    junction; the CC chain, with the same law and damping, has none."""
    torque = ["snr_db=none", "plant.actuation=torque"]
    free = linearize(load_scenario(None, torque), 1.0)
    lam = free.eigenvalues[0]
    assert free.verdict_class == "unstable"
    assert lam.real < -1.0 and abs(lam.imag) < 1e-9
    assert free.frequency(0) == pytest.approx(500.0)
    names = [n for n, _ in free.dominant(0, 4)]
    assert all("hinge" in n for n in names)
    assert {"octarm_s0_seg7_hinge", "octarm_s1_seg0_hinge"} <= set(names)
    cc = linearize(load_scenario(None, [*torque, "plant.enforce_cc=true"]), 1.0)
    assert cc.verdict_class != "unstable"
    assert min(e.real for e in cc.eigenvalues) > -1.0


def test_fd_jacobian_is_step_independent():
    """The central-difference Jacobian does not depend on the step (truncation and round-off small)."""
    scn = load_scenario(None, ["plant.kind=analytic", "snr_db=none", "duration=1", "transient=0.5"])
    a = linearize(scn, 0.3, h=1e-5)
    b = linearize(scn, 0.3, h=1e-7)
    assert np.max(np.abs(a.A - b.A)) < 1e-6 * max(1.0, np.max(np.abs(a.A)))


def test_cli_writes_spectrum_and_verdict(tmp_path, capsys):
    from harness.cli import main

    rc = main(["stability", "--plant", "analytic", "--at", "0.2", "--set", "snr_db=none",
               "--out", str(tmp_path), "--modes", "3"])
    text = capsys.readouterr().out
    assert rc == 0
    assert text.splitlines()[0].split(":")[0] in ("stable", "marginal")
    summary = json.loads((tmp_path / "stability.json").read_text())
    rows = (tmp_path / "spectrum.csv").read_text().splitlines()
    assert len(rows) == 1 + summary["n_states"] == 17
    assert (tmp_path / "stability.png").stat().st_size > 0


def test_cli_bad_time_is_one_line(capsys):
    from harness.cli import main

    rc = main(["stability", "--plant", "analytic", "--at", "-1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--at" in err[0] and "[0, 3600]" in err[0]


def test_python_controller_is_refused():
    from harness.studies.stability import LinearizationError

    scn = load_scenario(None, ["plant.kind=analytic", "controller.name=pd_joint"])
    with pytest.raises(LinearizationError, match="controller.name"):
        linearize(scn, 0.1)


def test_predicted_map_agrees_with_simulated_map():
    """k_n x eta_b on the free chain in torque actuation (2 x 3): "unstable" from the spectral radius along
    the run (linearized at 0, 0.5, 1 s) in exactly the cells whose simulation (1.5 s, same settings,
    `harness.studies.stability_map`) diverges."""
    from harness.studies.stability_map import predicted_map, stability_map

    kns, etas, ov = (10.0, 100.0), (0.001, 0.01, 1.0), ["plant.actuation=torque", "snr_db=none"]
    pred = predicted_map(kns, etas, ov, times=(0.0, 0.5, 1.0))
    simc = {(r["kn"], r["eta_b"]): r for r in stability_map(kns, etas, ov, duration=1.5)}
    # per cell: predicted diverging (class "unstable") against simulated diverging (status != "ok")
    cells = [{"kn": r["kn"], "eta_b": r["eta_b"], "predicted": r["class"], "radius": r["radius"],
              "simulated": simc[r["kn"], r["eta_b"]]["status"],
              "agree": (r["class"] == "unstable") == (simc[r["kn"], r["eta_b"]]["status"] != "ok")}
             for r in pred]
    assert all(c["agree"] for c in cells), cells
    # both outcomes occur on this grid (the test can tell a wrong edge from a right one)
    assert {c["simulated"] == "ok" for c in cells} == {True, False}


def test_cli_times_along_one_run(tmp_path, capsys):
    from harness.cli import main

    rc = main(["stability", "--plant", "analytic", "--at", "0:0.2:0.1", "--out", str(tmp_path)])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0
    assert [ln.split()[0] for ln in lines[1:4]] == ["0.000", "0.100", "0.200"]
    summary = json.loads((tmp_path / "stability.json").read_text())
    radii = [float(ln.split()[1]) for ln in lines[1:4]]
    assert summary["spectral_radius"] == pytest.approx(max(radii), abs=1e-6)


@pytest.mark.parametrize("sets", [
    ["plant.kind=analytic", "sensing.dq2_cutoff=200", "plant.actuation_delay=0.002"],
    pytest.param(["plant.kind=cosserat", "plant.actuation=muscle", "gains.kn=10"], marks=pytest.mark.slow),
], ids=["analytic_filter_delay", "rod_muscle"])
def test_loop_state_holds_every_state_of_the_loop(sets):
    """x() is the whole state of the one-period map: restoring x(k) after stepping on reproduces the same
    steps bit for bit (it fails if the sensed-dq2 filter, the delay ring or the rod's muscle forces were
    left out of x)."""
    from harness.studies.stability import ClosedLoopMap

    lp = ClosedLoopMap(load_scenario(None, [*sets, "snr_db=none", "duration=0.1"]))
    lp.run_to(20)
    lp.plant.get_state(keep=True)
    x0, k0 = lp.x(), lp.k
    lp.run_to(k0 + 10)
    first = lp.x()
    assert not np.array_equal(first, x0)
    lp.set_x(x0)
    lp.k = k0
    lp.run_to(k0 + 10)
    np.testing.assert_array_equal(lp.x(), first)
    assert any(n.endswith(("_filtered", ".force")) for n in lp.names)


def test_mujoco_warnings_are_captured_and_reported_not_printed(tmp_path, monkeypatch, capfd):
    """A 1 kHz servo on the MuJoCo chain makes MuJoCo raise mjWARN_BADQACC at 12 ms.  The linearization's
    run captures it as a run does (`harness.loop.mj_warnings`): its error gives the counts and MuJoCo's
    text as the Python-stepped run's message of the same scenario, and nothing reaches stdout, stderr or
    MuJoCo's log file (its default handler appends to MUJOCO_LOG.TXT in the working folder)."""
    from harness.cli import main
    from harness.loop.common import compile_model
    from harness.loop.stepped_loop import simulate_stepped
    from harness.loop.stepped_plants import stepped_plant
    from harness.plant import build_plant
    from harness.studies.stability import LinearizationError

    monkeypatch.chdir(tmp_path)
    sets = ["duration=0.05", "snr_db=none", "plant.servo_frequency=1000"]
    scn = load_scenario(None, sets)
    with pytest.raises(LinearizationError) as exc:
        linearize(scn, 0.03)
    msg = str(exc.value)
    assert "MuJoCo warning (mjWARN_BADQACC: 1); MuJoCo says: Nan, Inf or huge value in QACC" in msg, msg
    out, err = capfd.readouterr()
    assert "WARNING" not in out + err
    assert list(tmp_path.iterdir()) == []
    model = compile_model(scn)
    tr = simulate_stepped(scn, stepped_plant(scn, model, build_plant(scn)), model=model)
    assert msg == f"the run stopped before the point of linearization: {tr.message}"
    # `teleop stability`: the same one line, exit status 1
    rc = main(["stability", "--at", "0.03", *(a for s in sets for a in ("--set", s)), "--out", "st"])
    out, err = capfd.readouterr()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("teleop: compiling")]  # cold cache
    assert rc == 1 and lines == [f"error: {msg}"], err
    assert "WARNING" not in out and not (tmp_path / "MUJOCO_LOG.TXT").exists()
