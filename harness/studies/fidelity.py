"""Fidelity of the MuJoCo plant against the analytic models (`teleop fidelity`): slave quantities through
A = d qpos_chain / d q2 on the CC manifold, the master, and the chain with and without the CC constraints.
docs/plants.md, fidelity studies."""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np

from controllers import master as master_model
from controllers import slave as slave_model
from controllers.params import MasterParams, SlaveParams
from harness.config.scenario import PlantConfig
from harness.plant.mujoco_model import ChainMap, build_model
from harness.studies.figures import md_table, printer, pyplot, save, save_csv, save_figure

ROUNDING_LEVEL = 1e-12  # relative errors below this are rounding (no convergence order is shown)
QUANTITY_TEXT = {
    "tip": "tip position |dx| / sum(L0)",
    "jacobian": "tip Jacobian (scaled, spectral)",
    "mass": "M2, armature removed (scaled, spectral)",
    "gravity": "gravity force (scaled)",
    "elastic": "elastic force (scaled, with correction)",
    "armature": "armature share of M2 (modelled mismatch)",
}
QUANTITIES = tuple(QUANTITY_TEXT)


def sample_q2(slave: SlaveParams, n: int, seed: int = 0) -> np.ndarray:
    """(n, 6) random in-range q2: d_i ~ U[L0_i, max_extension L0_i], k_i d_i ~ U[-max_bend, max_bend]."""
    rng = np.random.default_rng(seed)
    lo, hi = slave.length_range
    d = rng.uniform(lo, hi, size=(n, 3))
    th = rng.uniform(-slave.max_bend, slave.max_bend, size=(n, 3))
    return np.concatenate([d, th / d], axis=1)


def q2_scales(slave: SlaveParams) -> np.ndarray:
    """Coordinate scales s (6,) = [L0 (m), max_bend / L0 (1/m)] making the errors dimensionless."""
    L0 = np.asarray(slave.rest_lengths)
    return np.concatenate([L0, slave.max_bend / L0])


def _rel(err: np.ndarray, ref: np.ndarray) -> float:
    order = 2 if err.ndim == 2 else None
    return float(np.linalg.norm(err, order) / np.linalg.norm(ref, order))


def slave_errors(m: mujoco.MjModel, cm: ChainMap, slave: SlaveParams, q2: np.ndarray,
                 d: mujoco.MjData | None = None) -> dict[str, float]:
    """Relative errors of the MuJoCo chain at one q2 (6,) on the CC manifold vs `controllers.slave`, in the
    coordinate scales s (`q2_scales`; spectral norms of matrices, 2-norms of vectors; tip: |dx| / sum(L0)).
    mass: armature removed; armature: its own share A^T diag(armature) A; elastic: with the correction."""
    d = mujoco.MjData(m) if d is None else d
    d.qpos[:] = m.qpos0
    d.qvel[:] = 0.0
    cm.set_q2(d, q2)
    mujoco.mj_forward(m, d)
    A = cm.jacobian(q2)
    s = q2_scales(slave)
    S = np.outer(s, s)
    idx = np.asarray(cm.chain_dof_adr)
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, None, cm.tip_site_id)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    arm = np.diag(np.asarray(m.dof_armature)[idx])
    M_ref = slave_model.mass_matrix(slave, q2)
    f_el = d.qfrc_spring[idx] + cm.elastic_correction(cm.chain_qpos(d))
    pairs = {  # quantity: (MuJoCo through A, analytic, scale)
        "jacobian": (jacp[[0, 2]][:, idx] @ A, slave_model.jacobian(slave, q2), s),
        "mass": (A.T @ (M[np.ix_(idx, idx)] - arm) @ A, M_ref, S),
        "gravity": (A.T @ d.qfrc_bias[idx], slave_model.gravity_force(slave, q2), s),
        "elastic": (-(A.T @ f_el), slave_model.elastic_force(slave, q2), s),
    }
    tip_err = np.linalg.norm(cm.octarm_tip(m, d) - slave_model.tip_position(slave, q2))
    out = {"tip": float(tip_err / np.sum(slave.rest_lengths)), "armature": _rel(A.T @ arm @ A * S, M_ref * S)}
    out.update({q: _rel((x - ref) * sc, ref * sc) for q, (x, ref, sc) in pairs.items()})
    return out


def master_errors(m: mujoco.MjModel, cm: ChainMap, master: MasterParams, q1, dq1=(0.0, 0.0),
                  d: mujoco.MjData | None = None) -> dict[str, float]:
    """Absolute errors of the MuJoCo master vs controllers.master at (q1, dq1): tip (m), jacobian, mass
    (kg m^2), gravity (bias at rest, N m), bias (with velocity, friction excluded, N m)."""
    d = mujoco.MjData(m) if d is None else d
    q1, dq1 = np.asarray(q1, float), np.asarray(dq1, float)
    da = np.asarray(cm.master_dof_adr)
    d.qpos[:] = m.qpos0
    d.qvel[:] = 0.0
    d.qpos[np.asarray(cm.master_qpos_adr)] = q1
    mujoco.mj_forward(m, d)
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, None, cm.master_site_id)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    out = {"tip": cm.master_tip(m, d) - master_model.fk(master, q1),
           "jacobian": jacp[[0, 2]][:, da] - master_model.jacobian(master, q1),
           "mass": M[np.ix_(da, da)] - master_model.mass_matrix(master, q1),
           "gravity": d.qfrc_bias[da] - master_model.gravity_force(master, q1)}
    d.qvel[da] = dq1
    mujoco.mj_forward(m, d)
    friction = np.asarray(master.damping) * dq1
    out["bias"] = d.qfrc_bias[da] - (master_model.nle(master, q1, dq1) - friction)
    return {k: float(np.abs(v).max()) for k, v in out.items()}


@dataclass
class FidelityTable:
    """Result of `fidelity_study`: per N the maximum relative error of each quantity."""

    Ns: tuple[int, ...]
    errors: dict[str, np.ndarray]  # quantity -> (len(Ns),)
    orders: dict[str, np.ndarray]  # quantity -> (len(Ns) - 1,) observed order between successive Ns
    master: dict[str, float]  # max absolute master errors
    n_samples: int
    seed: int

    def rows(self) -> list[dict]:
        out = []
        for k, N in enumerate(self.Ns):
            row = {"N": N}
            for q in QUANTITIES:
                row[q] = float(self.errors[q][k])
                row[f"{q}_order"] = float(self.orders[q][k - 1]) if k > 0 else float("nan")
            out.append(row)
        return out

    def to_markdown(self) -> str:
        cells = []
        for r in self.rows():
            cells.append([str(r["N"])])
            for q in QUANTITIES:
                o = r[f"{q}_order"]  # between two values at rounding level (elastic force): no order
                order = "" if np.isnan(o) else ("exact" if r[q] < ROUNDING_LEVEL else f"{o:.2f}")
                cells[-1] += [f"{r[q]:.3e}", order]
        head = ["N", *(f"{q} | order" for q in QUANTITIES)]
        lines = md_table(head, cells, ["---:"] * (1 + 2 * len(QUANTITIES)))
        lines += ["", f"max over {self.n_samples} random in-range q2 (seed {self.seed}); "
                  + "; ".join(f"{q}: {QUANTITY_TEXT[q]}" for q in QUANTITIES),
                  "master vs analytic (max abs): "
                  + ", ".join(f"{k} {v:.1e}" for k, v in self.master.items())]
        return "\n".join(lines)

    def write_csv(self, path) -> Path:
        return save_csv(path, self.rows())

    def write_markdown(self, path) -> Path:
        return save(path, self.to_markdown() + "\n")


def observed_orders(Ns, errs) -> np.ndarray:
    """log(err_k / err_{k+1}) / log(N_{k+1} / N_k) for successive entries (nan where undefined)."""
    Ns = np.asarray(Ns, float)
    errs = np.asarray(errs, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(errs[:-1] / errs[1:]) / np.log(Ns[1:] / Ns[:-1])


def fidelity_study(Ns=(4, 8, 16, 32), n_samples: int = 20, seed: int = 0, slave: SlaveParams | None = None,
                   plant: PlantConfig | None = None) -> FidelityTable:
    """`slave_errors` (max over n_samples q2) and `master_errors` per N segments per section; plant: template
    config whose `segments` is replaced by each N."""
    master = MasterParams()
    slave = SlaveParams() if slave is None else slave
    plant = PlantConfig() if plant is None else plant
    Ns = tuple(int(n) for n in Ns)
    q2s = sample_q2(slave, n_samples, seed)
    errors = {q: np.zeros(len(Ns)) for q in QUANTITIES}
    master_err: dict[str, float] = {}
    rng = np.random.default_rng(seed + 1)
    for k, N in enumerate(Ns):
        m, cm = build_model(master, slave, replace(plant, segments=N))
        d = mujoco.MjData(m)
        for q2 in q2s:
            e = slave_errors(m, cm, slave, q2, d)
            for q in QUANTITIES:
                errors[q][k] = max(errors[q][k], e[q])
        if k == 0:
            for _ in range(n_samples):
                q1 = rng.uniform(-np.pi, np.pi, 2)
                dq1 = rng.uniform(-3.0, 3.0, 2)
                for key, v in master_errors(m, cm, master, q1, dq1, d).items():
                    master_err[key] = max(master_err.get(key, 0.0), v)
    orders = {q: observed_orders(Ns, errors[q]) for q in QUANTITIES}
    return FidelityTable(Ns=Ns, errors=errors, orders=orders, master=master_err, n_samples=n_samples,
                         seed=seed)


def plot_fidelity(table: FidelityTable, path) -> Path:
    """Log-log plot of the relative errors vs N with N^-1 and N^-2 guides, saved to `path` (png/pdf/svg)."""
    import matplotlib.ticker

    plt = pyplot()
    Ns = np.asarray(table.Ns, float)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for q in QUANTITIES:
        if np.all(table.errors[q] > 0):
            ax.loglog(Ns, table.errors[q], "o-", label=QUANTITY_TEXT[q])
    ref = table.errors["mass"][0] if table.errors["mass"][0] > 0 else 1e-2
    ax.loglog(Ns, ref * (Ns / Ns[0]) ** -2, "k--", lw=0.8, label="$N^{-2}$")
    ax.loglog(Ns, ref * (Ns / Ns[0]) ** -1, "k:", lw=0.8, label="$N^{-1}$")
    ax.set_xticks(Ns)
    ax.set_xticklabels([str(int(n)) for n in Ns])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set(xlabel="segments per section N", ylabel="max relative error",
           title="MuJoCo Octarm vs analytic CC model")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def _held_bend(m: mujoco.MjModel, cm: ChainMap, slave: SlaveParams, q2: np.ndarray,
               settle_steps: int) -> tuple[float, float, np.ndarray]:
    """Servos hold q2 under gravity (static feed-forward + elastic correction): (tip, largest hinge departure
    from the CC chain at the sensed q2 (m, rad; nan if unstable), held commands (steps, nu + nv))."""
    d = mujoco.MjData(m)
    cm.set_q2(d, q2)
    d.ctrl[np.asarray(cm.chain_actuator_ids)] = cm.joints_from_q2(q2)
    ff = cm.force_from_T2(q2, slave_model.gravity_force(slave, q2) + slave_model.elastic_force(slave, q2))
    dof = np.asarray(cm.chain_dof_adr)
    for _ in range(settle_steps):
        d.qfrc_applied[dof] = ff + cm.elastic_correction(cm.chain_qpos(d))
        mujoco.mj_step(m, d)
    log = np.tile(np.concatenate([d.ctrl, d.qfrc_applied]), (settle_steps, 1))
    mujoco.mj_kinematics(m, d)
    q = cm.chain_qpos(d)
    q2_s = cm.q2_from_joints(q)
    if not (np.all(np.isfinite(q)) and warning_count(d) == 0):
        return float("nan"), float("nan"), log
    d_cc = mujoco.MjData(m)
    cm.set_q2(d_cc, q2_s)
    mujoco.mj_kinematics(m, d_cc)
    resid = (q - cm.joints_from_q2(q2_s))[np.asarray(cm.is_hinge) == 1]
    tip_dev = np.linalg.norm(cm.octarm_tip(m, d) - cm.octarm_tip(m, d_cc))
    return float(tip_dev), float(np.abs(resid).max()), log


def cc_study(Ns=(4, 8, 16, 32), n_samples: int = 4, seed: int = 0, settle_steps: int = 1500,
             loop_duration: float = 2.0, plant: PlantConfig | None = None) -> list[dict]:
    """The servo chain with and without the CC constraints: rows per N and enforce_cc: us_per_step (best of
    3 compiled replays of the held commands), tip_dev_mm, hinge_dev_mrad (max over n_samples `_held_bend`),
    closed_loop (the paper scenario on that plant for loop_duration s: status, time if it diverged)."""
    from harness.config.scenario import Scenario
    from harness.loop.fast import K
    from harness.loop.mujoco_loop import simulate_mujoco
    from harness.loop.native import MJ_FUNCS

    master, slave = MasterParams(), SlaveParams()
    plant = PlantConfig() if plant is None else plant
    q2s = sample_q2(slave, n_samples, seed)
    rows = []
    for N, cc in itertools.product(Ns, (True, False)):
        p = replace(plant, segments=int(N), enforce_cc=cc, actuation="servo")
        m, cm = build_model(master, slave, p)
        held = [_held_bend(m, cm, slave, q2, settle_steps) for q2 in q2s]
        tip_dev, hinge_dev = (max(h[i] for h in held) for i in (0, 1))
        if not all(np.isfinite(h[0]) for h in held):
            tip_dev = hinge_dev = float("nan")
        log = held[-1][2]
        best = np.inf
        for _ in range(3):
            d = mujoco.MjData(m)
            cm.set_q2(d, q2s[-1])
            t0 = time.perf_counter()
            K.replay_commands(m._address, d._address, MJ_FUNCS, d.ctrl, d.qfrc_applied, log)
            best = min(best, time.perf_counter() - t0)
        tr = simulate_mujoco(Scenario(duration=loop_duration, plant=p, master=master, slave=slave))
        loop = "ok" if tr.status == "ok" else f"{tr.status} at t = {tr.t[-1]:.3f} s"
        rows.append({"N": int(N), "enforce_cc": cc, "us_per_step": best / len(log) * 1e6,
                     "tip_dev_mm": tip_dev * 1e3, "hinge_dev_mrad": hinge_dev * 1e3, "closed_loop": loop})
    return rows


def cc_markdown(rows: list[dict], n_samples: int, settle_steps: int, loop_duration: float) -> str:
    head = ["N", "CC enforced", "mj_step (us)", "tip off the CC shape (mm)", "hinge off CC (mrad)",
            f"closed loop, paper scenario {loop_duration:g} s"]
    cells = [[str(r["N"]), "yes" if r["enforce_cc"] else "no", f"{r['us_per_step']:.1f}",
              f"{r['tip_dev_mm']:.3f}", f"{r['hinge_dev_mrad']:.2f}", r["closed_loop"]] for r in rows]
    return "\n".join([*md_table(head, cells, ["---:", ":---:", "---:", "---:", "---:", "---"]), "",
                      f"servos holding {n_samples} random bent q2 under gravity for {settle_steps} steps "
                      "(static feed-forward + elastic correction); max over the samples; mj_step = compiled "
                      "replay of the held commands, best of 3."])


def worst_case_markdown(segments, seed: int = 0) -> str:
    """Table of `fidelity_reference.worst_tip_error` for each N: error, in mm of sum(L0), and where."""
    from harness.studies.fidelity_reference import worst_tip_error

    slave = SlaveParams()
    L = float(np.sum(slave.rest_lengths))
    cells = []
    for N in segments:
        e, q = worst_tip_error(int(N), seed=seed)
        cells.append([str(int(N)), f"{e:.3e}", f"{e * L * 1e3:.2f}", str(np.round(q[:3], 3).tolist()),
                      str(np.round(q[3:] * q[:3], 3).tolist())])
    head = ["N", "worst tip error (rel.)", "mm", "at d (m)", "at k d (rad)"]
    return "\n".join(md_table(head, cells, ["---:", "---:", "---:", "---", "---"]))


def main_fidelity(segments, out, progress: bool = True, samples: int = 50, seed: int = 0,
                  cc_samples: int = 4) -> int:
    """`teleop fidelity`: the discretization table (fidelity.md/.csv/.png), the worst case
    (fidelity_worst.md) and the CC study (fidelity_cc.md/.csv) for the given N, printed and written."""
    out, say, Ns = Path(out), printer(progress), tuple(segments)
    say(f"discretization errors at {samples} random q2 for N = {', '.join(map(str, Ns))} ...")
    table = fidelity_study(Ns=Ns, n_samples=samples, seed=seed)
    written = [table.write_markdown(out / "fidelity.md"), table.write_csv(out / "fidelity.csv"),
               plot_fidelity(table, out / "fidelity.png")]
    print(table.to_markdown())
    say("worst-case tip error by optimization (corners + random starts + Nelder-Mead) ...")
    worst = worst_case_markdown(Ns, seed)
    written.append(save(out / "fidelity_worst.md", worst + "\n"))
    print(f"\n{worst}")
    say("constant curvature enforced vs free chain (held bends, mj_step cost, closed loop) ...")
    settle, loop = 1500, 2.0
    rows = cc_study(Ns=Ns, n_samples=cc_samples, seed=seed, settle_steps=settle, loop_duration=loop)
    text = cc_markdown(rows, cc_samples, settle, loop)
    written += [save(out / "fidelity_cc.md", text + "\n"), save_csv(out / "fidelity_cc.csv", rows)]
    print(f"\n{text}")
    print(f"outputs in {out}/: " + ", ".join(p.name for p in written))
    return 0


def warning_count(d: mujoco.MjData) -> int:
    """Total number of MuJoCo warnings of every kind recorded in d."""
    return int(sum(d.warning[int(w)].number for name, w in mujoco.mjtWarning.__members__.items()
                   if name != "mjNWARNING"))
