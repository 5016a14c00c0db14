"""Fidelity against the Cosserat rod (`teleop fidelity --reference cosserat`): the analytic CC model, the
MuJoCo chain (CC on / off) and the rod (`linear` law) as passive rods at rest at a commanded q2c: statics,
small motion, worst-case discretization tip error and the paper scenario's closed loop on each plant."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import mujoco
import numpy as np

from controllers import slave as slave_model
from controllers.params import MasterParams, SlaveParams
from harness.config.scenario import PlantConfig
from harness.plant.mujoco_model import build_model
from harness.studies.figures import md_table, printer, pyplot, run_paper, save, save_figure

SETTLE_DAMPING = 30.0  # x damping while settling to a static equilibrium (statics do not depend on it)
SETTLE_V_TOL = 1e-6  # m/s, tip speed below which a settling body is at its static equilibrium
SETTLE_WINDOW = 0.05  # s, window over which the tip speed is measured
SETTLE_MAX = 30.0  # s, longest settling
TIP_LOAD = (1.0, 0.0)  # N, [FX, FZ] tip load of the static and release tests
LOADS = {"gravity": (0.0, 0.0), "gravity + 1 N tip": TIP_LOAD}


def static_shapes(slave: SlaveParams) -> dict[str, np.ndarray]:
    """Named commanded q2c (6,): straight, uniform C, extended C, S, and alternating +-max_bend at full
    extension (the discretization's worst case)."""
    L0 = np.asarray(slave.rest_lengths, float)
    b = slave.max_bend

    def q(d, th):
        d = np.asarray(d, float)
        return np.concatenate([d, np.asarray(th, float) / d])

    return {"straight": q(L0, [0.0, 0.0, 0.0]), "C 0.8 rad": q(L0, [0.8, 0.8, 0.8]),
            "C extended": q(1.25 * L0, [1.2, 1.2, 1.2]), "S": q(1.1 * L0, [1.0, -1.0, 1.0]),
            "alternating max": q(slave.max_extension * L0, [b, -b, b])}


def cc_gradient(slave: SlaveParams, q2, q2c, F=(0.0, 0.0)) -> np.ndarray:
    """dV/dq2 (6,) of V = gravity + 1/2 Kb (k d - k_c d_c)^2 / L0 + 1/2 Ke (d - d_c)^2 - F . tip."""
    q2, q2c = np.asarray(q2, float), np.asarray(q2c, float)
    d, k, dc, kc = q2[:3], q2[3:], q2c[:3], q2c[3:]
    Kb, Ke, L0 = (np.asarray(v, float) for v in (slave.bending_stiffness, slave.extension_stiffness,
                                                 slave.rest_lengths))
    m = Kb * (k * d - kc * dc) / L0
    g_el = np.concatenate([m * k + Ke * (d - dc), m * d])
    J = slave_model.jacobian(slave, q2)
    return slave_model.gravity_force(slave, q2) + g_el - J.T @ np.asarray(F, float)


def _hessian(f, q, h=1e-6) -> np.ndarray:
    H = np.empty((6, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = h * max(1.0, abs(q[i]))
        H[:, i] = (f(q + e) - f(q - e)) / (2 * e[i])
    return 0.5 * (H + H.T)


def cc_static(slave: SlaveParams, q2c, F=(0.0, 0.0), tol=1e-12, iters=60) -> np.ndarray:
    """Static equilibrium q2 (6,) of the CC model under tip force F (N; Newton, backtracking on |grad|)."""
    q = np.asarray(q2c, float).copy()

    def g(x):
        return cc_gradient(slave, x, q2c, F)

    for _ in range(iters):
        r = g(q)
        if np.linalg.norm(r) < tol:
            break
        step = np.linalg.solve(_hessian(g, q), r)
        a = 1.0
        while a > 1e-4 and np.linalg.norm(g(q - a * step)) > np.linalg.norm(r):
            a *= 0.5
        q = q - a * step
    return q


def cc_modes(slave: SlaveParams, q2c, eta_b, eta_a) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies (6,) Hz ascending, damping ratios (6,)) of the CC model linearized at its gravity
    equilibrium for rest shape q2c, material damping eta_b (N m^2 s), eta_a (N s) per section."""
    q = cc_static(slave, q2c)
    K = _hessian(lambda x: cc_gradient(slave, x, q2c), q)
    M = slave_model.mass_matrix(slave, q)
    L0 = np.asarray(slave.rest_lengths, float)
    D = np.diag(np.concatenate([np.broadcast_to(eta_a, 3) / L0, np.broadcast_to(eta_b, 3) * L0]))
    Li = np.linalg.inv(np.linalg.cholesky(M))
    w2, V = np.linalg.eigh(Li @ K @ Li.T)
    phi = Li.T @ V
    w = np.sqrt(np.maximum(w2, 0.0))
    zeta = np.array([phi[:, i] @ D @ phi[:, i] / (2 * w[i] * (phi[:, i] @ M @ phi[:, i])) for i in range(6)])
    return w / (2 * np.pi), zeta


def _settle(advance, tip, t_max: float) -> bool:
    """advance() by SETTLE_WINDOW until the tip speed is below SETTLE_V_TOL in two successive windows
    (True), or t_max s have passed (False)."""
    calm, t, x = 0, 0.0, tip()
    while t < t_max:
        advance()
        t += SETTLE_WINDOW
        x, x0 = tip(), x
        calm = calm + 1 if np.linalg.norm(x - x0) < SETTLE_V_TOL * SETTLE_WINDOW else 0
        if calm >= 2:
            return True
    return False


class PassiveChain:
    """The MuJoCo chain (N, enforce_cc) as a passive rod: torque actuation, zero commands, joint springs
    at rest at joints_from_q2(q2c), material damping (eta_b, eta_a), optional tip force."""

    def __init__(self, slave: SlaveParams, N: int, enforce_cc: bool, eta_b, eta_a, dt: float = 1e-3):
        plant = PlantConfig(segments=int(N), enforce_cc=bool(enforce_cc), actuation="torque", physics_dt=dt,
                            bending_viscosity=tuple(np.broadcast_to(eta_b, 3).astype(float)),
                            extension_viscosity=tuple(np.broadcast_to(eta_a, 3).astype(float)))
        self.m, self.cm = build_model(MasterParams(), slave, plant)
        self.d = mujoco.MjData(self.m)
        self.dof = np.asarray(self.cm.chain_dof_adr)
        self.damping0 = self.m.dof_damping.copy()
        self.tip_body = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, "octarm_tip_body")
        self.m.dof_damping[np.asarray(self.cm.master_dof_adr)] = 1e6  # the master (not tested) held still

    def reset(self, q2c) -> None:
        mujoco.mj_resetData(self.m, self.d)
        self.m.qpos_spring[np.asarray(self.cm.chain_qpos_adr)] = self.cm.joints_from_q2(q2c)
        self.cm.set_q2(self.d, q2c)
        mujoco.mj_forward(self.m, self.d)

    def force(self, F) -> None:
        """Tip force F = [FX, FZ] (N) from now on."""
        self.d.xfrc_applied[self.tip_body, :] = 0.0
        self.d.xfrc_applied[self.tip_body, [0, 2]] = F

    def run(self, T: float, damping_scale: float = 1.0, sample=None) -> np.ndarray | None:
        """Step T s with the chain's damping scaled; sample: return the tip (n, 2) after every step."""
        self.m.dof_damping[self.dof] = self.damping0[self.dof] * damping_scale
        n = int(round(T / self.m.opt.timestep))
        out = np.empty((n, 2)) if sample else None
        for k in range(n):
            mujoco.mj_step(self.m, self.d)
            if out is not None:
                out[k] = self.tip()
        self.m.dof_damping[self.dof] = self.damping0[self.dof]
        return out

    def settle(self, t_max: float = SETTLE_MAX, damping_scale: float = SETTLE_DAMPING) -> bool:
        return _settle(lambda: self.run(SETTLE_WINDOW, damping_scale), self.tip, t_max)

    def tip(self) -> np.ndarray:
        return self.cm.octarm_tip(self.m, self.d)

    def sense(self) -> np.ndarray:
        return self.cm.q2_from_joints(self.cm.chain_qpos(self.d))

    def ok(self) -> bool:
        return bool(np.all(np.isfinite(self.d.qpos)))


def _rod(slave: SlaveParams, eta_b, eta_a):
    from harness.plant.cosserat import CosseratSlave

    return CosseratSlave(slave, actuation="servo", elastic_law="linear", material_damping=(eta_b, eta_a))


def _rod_settled(slave, q2c, F, eta_b, eta_a, t_max=SETTLE_MAX):
    # both viscosities raised so that the axial modes settle too; the explicit extension part 10x only
    r = _rod(slave, SETTLE_DAMPING * np.asarray(eta_b), 10.0 * np.asarray(eta_a))
    r.reset(q2c)
    r.external_tip_force(F)
    w = round(SETTLE_WINDOW / r.dt) * r.dt
    r.converged = _settle(lambda: r.step(q2c, w), r.tip, t_max)
    return r


def static_comparison(Ns=(4, 8, 16, 32), settle: float = SETTLE_MAX, say=lambda s: None) -> list[dict]:
    """Rows: model, N, enforce_cc, tip_err_mm (max over shapes x loads of |tip - rod tip|), cc_dev_mm
    (max |tip - CC tip of the body's sensed q2|), worst (shape / load of the max tip error, with "not
    converged" where a body did not settle within `settle` s); paper slave, eta_b 0.01, eta_a 0.3."""
    slave, eta_b, eta_a = SlaveParams(), 0.01, 0.3
    shapes = static_shapes(slave)
    ref = {}
    rod_dev, rod_note = 0.0, ""
    for sn, q2c in shapes.items():
        for ln, F in LOADS.items():
            r = _rod_settled(slave, q2c, F, eta_b, eta_a, settle)
            if not r.converged:
                rod_note = f"{sn} / {ln}: rod not converged"
            ref[sn, ln] = r.tip()
            cc_tip = slave_model.tip_position(slave, r.sense()[0])
            rod_dev = max(rod_dev, float(np.linalg.norm(r.tip() - cc_tip)))
    say("rod statics done")
    rows = [{"model": "Cosserat rod (reference)", "N": 10, "enforce_cc": False, "tip_err_mm": 0.0,
             "cc_dev_mm": rod_dev * 1e3, "worst": rod_note}]
    err, worst = 0.0, ""
    for (sn, ln), tip in ref.items():
        q = cc_static(slave, shapes[sn], LOADS[ln])
        e = float(np.linalg.norm(slave_model.tip_position(slave, q) - tip))
        if e > err:
            err, worst = e, f"{sn} / {ln}"
    rows.append({"model": "analytic CC", "N": 0, "enforce_cc": True, "tip_err_mm": err * 1e3,
                 "cc_dev_mm": 0.0, "worst": worst})
    for N, cc in itertools.product(Ns, (True, False)):
        ch = PassiveChain(slave, N, cc, eta_b, eta_a)
        err, dev, worst, note = 0.0, 0.0, "", ""
        for (sn, ln), tip in ref.items():
            ch.reset(shapes[sn])
            ch.force(LOADS[ln])
            converged = ch.settle(settle)
            if not ch.ok():
                err, worst = float("nan"), f"{sn} / {ln}: diverged"
                break
            if not converged:
                note = f"; {sn} / {ln}: not converged"
            e = float(np.linalg.norm(ch.tip() - tip))
            dev = max(dev, float(np.linalg.norm(ch.tip() - slave_model.tip_position(slave, ch.sense()))))
            if e > err:
                err, worst = e, f"{sn} / {ln}"
        rows.append({"model": "MuJoCo chain", "N": int(N), "enforce_cc": cc, "tip_err_mm": err * 1e3,
                     "cc_dev_mm": dev * 1e3, "worst": worst + note})
        say(f"statics N = {N} cc = {cc}: {err * 1e3:.2f} mm")
    return rows


def upward_crossings(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices k with y[k] < 0 <= y[k+1], the crossing times interpolated linearly)."""
    up = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    return up, t[up] - y[up] * (t[up + 1] - t[up]) / (y[up + 1] - y[up])


def fit_decay(t: np.ndarray, x: np.ndarray, x_eq: float, skip: float = 0.5) -> tuple[float, float]:
    """(frequency Hz, damping ratio) of the oscillation of x(t) about x_eq after t >= skip (s): mean spacing
    of upward zero crossings; zeta = delta / sqrt(4 pi^2 + delta^2), delta the log decrement of the positive
    peaks (least squares).  nan when fewer than two periods are seen."""
    y = np.asarray(x, float) - x_eq
    keep = t >= skip
    t, y = t[keep], y[keep]
    up, tc = upward_crossings(t, y)
    if len(up) < 3:
        return float("nan"), float("nan")
    period = (tc[-1] - tc[0]) / (len(tc) - 1)
    peaks = np.array([y[a:b].max() for a, b in zip(up[:-1], up[1:], strict=True)])
    if np.any(peaks <= 0):
        return 1.0 / period, float("nan")
    delta = -np.polyfit(np.arange(len(peaks)), np.log(peaks), 1)[0]
    return 1.0 / period, float(delta / np.sqrt(4 * np.pi**2 + delta**2))


def modal_comparison(Ns=(4, 8, 16, 32), release_time: float = 4.0, settle: float = SETTLE_MAX,
                     say=lambda s: None) -> list[dict]:
    """Rows: model, N, enforce_cc, f1_hz, zeta1 (first bending mode, released 1 N tip deflection of the
    straight arm at rest length; the analytic CC row is its linearization); as `static_comparison`."""
    slave, eta_b, eta_a = SlaveParams(), 0.01, 0.3
    q2c = static_shapes(slave)["straight"]
    # rod: equilibrium under the load with raised damping, copied into a rod with the default damping
    r0 = _rod_settled(slave, q2c, TIP_LOAD, eta_b, eta_a, settle)
    eq = _rod_settled(slave, q2c, (0.0, 0.0), eta_b, eta_a, settle).tip()[0]
    r = _rod(slave, eta_b, eta_a)
    r.reset(q2c)
    for name in ("position_collection", "director_collection"):
        getattr(r._b, name)[:] = getattr(r0._b, name)
    n, k = int(round(release_time / 1e-3)), round(1e-3 / r.dt)
    x = np.empty(n)
    for i in range(n):
        r.step(q2c, k * r.dt)
        x[i] = r.tip()[0]
    f, z = fit_decay(np.arange(1, n + 1) * 1e-3, x, eq)
    say(f"rod release: {f:.3f} Hz, zeta {z:.4f}")
    fcc, zcc = cc_modes(slave, q2c, eta_b, eta_a)
    rows = [{"model": "Cosserat rod (reference)", "N": 10, "enforce_cc": False, "f1_hz": f, "zeta1": z},
            {"model": "analytic CC", "N": 0, "enforce_cc": True, "f1_hz": float(fcc[0]),
             "zeta1": float(zcc[0])}]
    for N, cc in itertools.product(Ns, (True, False)):
        ch = PassiveChain(slave, N, cc, eta_b, eta_a)
        ch.reset(q2c)
        ch.settle(settle)
        x_eq = ch.tip()[0]
        ch.force(TIP_LOAD)
        ch.settle(settle)
        ch.force((0.0, 0.0))
        xs = ch.run(release_time, 1.0, sample=True)
        f, z = fit_decay(np.arange(1, len(xs) + 1) * ch.m.opt.timestep, xs[:, 0], x_eq)
        rows.append({"model": "MuJoCo chain", "N": int(N), "enforce_cc": cc, "f1_hz": f, "zeta1": z})
        say(f"release N = {N} cc = {cc}: {f:.3f} Hz, zeta {z:.4f}")
    return rows


def worst_tip_error(N: int, n_random: int = 32, n_refine: int = 6, seed: int = 0) -> tuple[float, np.ndarray]:
    """Largest relative tip error |tip_MuJoCo - tip_CC| / sum(L0) over the in-range q2 box, the chain on
    the CC manifold: the 64 corners (each length and bend at an end of its range) and n_random random
    points, the n_refine best refined by scipy's bounded Nelder-Mead in (d, k d).  Returns (error, q2)."""
    from scipy.optimize import minimize

    slave = SlaveParams()
    m, cm = build_model(MasterParams(), slave, PlantConfig(actuation="torque", segments=int(N)))
    d = mujoco.MjData(m)
    lo_d, hi_d = slave.length_range
    lo = np.concatenate([lo_d, [-slave.max_bend] * 3])
    hi = np.concatenate([hi_d, [slave.max_bend] * 3])
    L = float(np.sum(slave.rest_lengths))

    def err(x):  # x = [d, theta]: the tip part of fidelity.slave_errors, kinematics only
        q2 = np.concatenate([x[:3], x[3:] / x[:3]])
        cm.set_q2(d, q2)
        mujoco.mj_kinematics(m, d)
        return -float(np.linalg.norm(cm.octarm_tip(m, d) - slave_model.tip_position(slave, q2))) / L

    starts = [np.where([(s >> j) & 1 for j in range(6)], hi, lo) for s in range(64)]
    rng = np.random.default_rng(seed)
    starts += [rng.uniform(lo, hi) for _ in range(n_random)]
    vals = [err(x) for x in starts]
    best = min((minimize(err, starts[i], method="Nelder-Mead", bounds=list(zip(lo, hi, strict=True)),
                         options={"maxiter": 400, "xatol": 1e-10, "fatol": 1e-14})
                for i in np.argsort(vals)[:n_refine]), key=lambda r: r.fun)
    return -float(best.fun), np.concatenate([best.x[:3], best.x[3:] / best.x[:3]])


METRICS_MM = {"e2_rms_mm": "e2_rms", "e2_max_mm": "e2_max", "beta_min": "beta_min",
              "range_violation_mm": "range_violation"}  # column: metric (m, shown in mm when "_mm")


def closed_loop_rows(N: int = 8, duration: float = 20.0, seed: int = 0, say=lambda s: None) -> list[dict]:
    """The paper scenario (servo) on each plant: analytic, MuJoCo chain CC on / off at N, Cosserat rod."""
    cases = [("analytic CC (RK4)", ["plant.kind=analytic"]),
             (f"MuJoCo chain N = {N}, CC on", [f"plant.segments={N}", "plant.enforce_cc=true"]),
             (f"MuJoCo chain N = {N}, CC off (default)", [f"plant.segments={N}", "plant.enforce_cc=false"]),
             ("Cosserat rod", ["plant.kind=cosserat"])]
    rows = []
    for name, sets in cases:
        tr, m = run_paper([*sets, f"duration={duration}", f"seed={seed}"])
        status = tr.status if tr.status == "ok" else f"{tr.status}: {tr.message}"
        values = {c: (1e3 if c.endswith("_mm") else 1) * m.get(k, np.nan) for c, k in METRICS_MM.items()}
        rows.append({"plant": name, "status": status, **values})
        say(f"closed loop {name}: {rows[-1]['status']}")
    return rows


def _md(rows: list[dict], cols: dict[str, str]) -> str:
    def f(v):
        if isinstance(v, bool):
            return "on" if v else "off"
        return f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v)

    cells = [[f(r[c]) for c in cols] for r in rows]
    return "\n".join(md_table(list(cols.values()), cells, ["---"] * len(cols)))


def plot_reference(static_rows, modal_rows, path) -> Path:
    """Static tip error vs the rod and first-mode frequency vs N (CC on / off, analytic and rod lines)."""
    fig, (a, b) = pyplot().subplots(1, 2, figsize=(9.6, 3.8))
    for cc, st in ((True, "s-"), (False, "o-")):
        for ax, rows, key in ((a, static_rows, "tip_err_mm"), (b, modal_rows, "f1_hz")):
            rs = [r for r in rows if r["model"] == "MuJoCo chain" and r["enforce_cc"] == cc]
            ax.semilogx([r["N"] for r in rs], [r[key] for r in rs], st, base=2,
                        label=f"MuJoCo chain, CC {'on' if cc else 'off'}")
    cc_static_err = next(r["tip_err_mm"] for r in static_rows if r["model"] == "analytic CC")
    a.axhline(cc_static_err, color="k", ls="--", lw=0.8, label="analytic CC")
    for r in modal_rows:
        if r["model"] != "MuJoCo chain":
            b.axhline(r["f1_hz"], ls="--" if r["model"] == "analytic CC" else ":", color="k", lw=0.8,
                      label=r["model"])
    a.set(ylabel="max static tip error vs rod (mm)")
    a.set_title("statics (gravity, 1 N tip load)", fontsize=9)
    b.set(ylabel="first bending mode (Hz)")
    b.set_title("released 1 N tip deflection", fontsize=9)
    for ax in (a, b):
        ax.set_xlabel("segments per section N")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def main_reference(segments, out, progress: bool = True, seed: int = 0, loop_duration: float = 20.0) -> int:
    """`teleop fidelity --reference cosserat`: fidelity_reference.md, .json and .png in `out`."""
    out, say = Path(out), printer(progress)
    Ns = tuple(int(n) for n in segments)
    st = static_comparison(Ns=Ns, say=say)
    mo = modal_comparison(Ns=Ns, say=say)
    cl = closed_loop_rows(8, loop_duration, seed, say=say)
    text = "\n\n".join([
        "Statics: max over 5 commanded shapes x 2 loads (gravity; + 1 N tip force along +X)\n\n"
        + _md(st, {"model": "model", "N": "N", "enforce_cc": "CC", "tip_err_mm": "tip vs rod (mm)",
                   "cc_dev_mm": "own departure from CC (mm)", "worst": "worst case"}),
        "Small motion: straight arm released from a 1 N tip deflection (default material damping)\n\n"
        + _md(mo, {"model": "model", "N": "N", "enforce_cc": "CC", "f1_hz": "f1 (Hz)", "zeta1": "zeta1"}),
        f"Closed loop: paper scenario, servo, {loop_duration:g} s, seed {seed}\n\n"
        + _md(cl, {"plant": "plant", "status": "status", "e2_rms_mm": "e2 RMS (mm)",
                   "e2_max_mm": "e2 max (mm)", "beta_min": "beta min",
                   "range_violation_mm": "range violation (mm)"})])
    save(out / "fidelity_reference.md", text + "\n")
    save(out / "fidelity_reference.json", json.dumps({"static": st, "modal": mo, "closed_loop": cl}, indent=1,
                                                     default=float))
    plot_reference(st, mo, out / "fidelity_reference.png")
    print(text)
    print(f"outputs in {out}/: fidelity_reference.md, fidelity_reference.json, fidelity_reference.png")
    return 0
