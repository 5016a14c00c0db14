"""Fidelity of the MuJoCo plant against the analytic models (controllers.master / controllers.slave).

Slave: at seeded random in-range q2 (d in [L0, max_extension L0], |k d| <= max_bend) the discretized
Octarm is put on the constant-curvature manifold (qpos_chain = joints_from_q2(q2)) and compared with the
analytic model through A = d qpos_chain / d q2:

* tip position: ``octarm_tip_site`` (mj_kinematics) vs ``slave.tip_position``;
* tip Jacobian: ``mj_jacSite`` (x and z rows, chain columns) times A vs ``slave.jacobian``;
* inertia: A^T M_chain A vs ``slave.mass_matrix`` (M from ``mj_fullM``, chain block).  The joint
  armature (a deliberate regularizer) is subtracted for the discretization error ("mass") and its own
  contribution A^T diag(armature) A is reported separately ("armature");
* gravity: A^T qfrc_bias_chain (zero velocity) vs ``slave.gravity_force`` (= dV_gravity/dq2);
* elasticity: -A^T (qfrc_spring_chain + elastic correction) vs ``slave.elastic_force`` (= dV_el/dq2).

Errors are made dimensionless with the coordinate scales s = [L0_1..3, max_bend / L0_1..3] (so
q2 / s is O(1)): J s, diag(s) M diag(s), diag(s) f; matrix errors are spectral norms, vector errors
2-norms, each relative to the norm of the analytic value; the table holds the maximum over samples.
The observed order between two resolutions is log(err_N / err_N') / log(N' / N).

Master: MuJoCo inertia, bias (gravity at rest, plus Coriolis with velocity), tip site and site
Jacobian vs ``controllers.master`` (must agree to ~1e-12).

Constant curvature enforced or not (``cc_study``): the same chain with and without the equality
constraints (``plant.enforce_cc``), servo actuation.  At seeded random bent q2 the servos hold the
commanded shape under gravity with the analytic static feed-forward (gravity + elastic T2 mapped by
virtual work, as the harness does) and the elastic correction, for ``settle_steps`` physics steps;
then the chain's departure from constant curvature is measured: the tip site against the tip of the
same discrete chain put on the CC manifold at the sensed q2 (so the discretization error of the
table above cancels), and the largest hinge angle's departure from its section's CC value.  Also:
mj_step cost (compiled replay of the held commands) and whether the paper scenario's closed loop
runs (``loop_duration`` s).  A real continuum arm is not exactly CC; the free chain shows how far
gravity alone bends it away, the constrained one how tightly the soft equalities hold.
"""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from controllers import master as master_model
from controllers import slave as slave_model
from controllers.params import MasterParams, SlaveParams
from harness.config.scenario import PlantConfig
from harness.config.textio import write_atomic
from harness.plant.mujoco_model import ChainMap, build_model

ROUNDING_LEVEL = 1e-12  # relative errors below this are rounding (no convergence order is shown)
QUANTITIES = ("tip", "jacobian", "mass", "gravity", "elastic", "armature")
QUANTITY_TEXT = {
    "tip": "tip position |dx| / sum(L0)",
    "jacobian": "tip Jacobian (scaled, spectral)",
    "mass": "M2, armature removed (scaled, spectral)",
    "gravity": "gravity force (scaled)",
    "elastic": "elastic force (scaled, with correction)",
    "armature": "armature share of M2 (modelled mismatch)",
}


def sample_q2(slave: SlaveParams, n: int, seed: int = 0) -> np.ndarray:
    """(n, 6) random in-range q2: d_i ~ U[L0_i, max_extension L0_i], k_i d_i ~ U[-max_bend, max_bend]."""
    rng = np.random.default_rng(seed)
    lo, hi = slave.length_range
    d = rng.uniform(lo, hi, size=(n, 3))
    th = rng.uniform(-slave.max_bend, slave.max_bend, size=(n, 3))
    return np.concatenate([d, th / d], axis=1)


def q2_scales(slave: SlaveParams) -> np.ndarray:
    """Coordinate scales s (6,) = [L0 (m), max_bend / L0 (1/m)] used to make errors dimensionless."""
    L0 = np.asarray(slave.rest_lengths)
    return np.concatenate([L0, slave.max_bend / L0])


def _rel(err: np.ndarray, ref: np.ndarray) -> float:
    if err.ndim == 2:
        return float(np.linalg.norm(err, 2) / np.linalg.norm(ref, 2))
    return float(np.linalg.norm(err) / np.linalg.norm(ref))


def slave_errors(m: mujoco.MjModel, cm: ChainMap, slave: SlaveParams, q2: np.ndarray,
                 d: mujoco.MjData | None = None) -> dict[str, float]:
    """Relative errors (see module docstring) of the MuJoCo chain at one q2 (6,) on the CC manifold."""
    d = mujoco.MjData(m) if d is None else d
    d.qpos[:] = m.qpos0
    d.qvel[:] = 0.0
    cm.set_q2(d, q2)
    mujoco.mj_forward(m, d)
    A = cm.jacobian(q2)
    s = q2_scales(slave)
    idx = np.asarray(cm.chain_dof_adr)

    tip = cm.octarm_tip(m, d)
    tip_ref = slave_model.tip_position(slave, q2)
    out = {"tip": float(np.linalg.norm(tip - tip_ref) / np.sum(slave.rest_lengths))}

    jacp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, None, cm.tip_site_id)
    J = jacp[[0, 2]][:, idx] @ A
    J_ref = slave_model.jacobian(slave, q2)
    out["jacobian"] = _rel((J - J_ref) * s, J_ref * s)

    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    Mc = M[np.ix_(idx, idx)]
    arm = np.diag(np.asarray(m.dof_armature)[idx])
    M2 = A.T @ (Mc - arm) @ A
    M2_arm = A.T @ arm @ A
    M_ref = slave_model.mass_matrix(slave, q2)
    S = np.outer(s, s)
    out["mass"] = _rel((M2 - M_ref) * S, M_ref * S)
    out["armature"] = _rel(M2_arm * S, M_ref * S)

    G = A.T @ d.qfrc_bias[idx]
    G_ref = slave_model.gravity_force(slave, q2)
    out["gravity"] = _rel((G - G_ref) * s, G_ref * s)

    q = cm.chain_qpos(d)
    f_el = d.qfrc_spring[idx] + cm.elastic_correction(q)
    E = -(A.T @ f_el)
    E_ref = slave_model.elastic_force(slave, q2)
    out["elastic"] = _rel((E - E_ref) * s, E_ref * s)
    return out


def master_errors(m: mujoco.MjModel, cm: ChainMap, master: MasterParams, q1, dq1=(0.0, 0.0),
                  d: mujoco.MjData | None = None) -> dict[str, float]:
    """Absolute errors of the MuJoCo master vs controllers.master at (q1, dq1):
    tip (m), jacobian, mass (kg m^2), gravity (bias at rest, N m), bias (with velocity, friction
    excluded, N m)."""
    d = mujoco.MjData(m) if d is None else d
    q1, dq1 = np.asarray(q1, float), np.asarray(dq1, float)
    qa, da = np.asarray(cm.master_qpos_adr), np.asarray(cm.master_dof_adr)
    d.qpos[:] = m.qpos0
    d.qvel[:] = 0.0
    d.qpos[qa] = q1
    mujoco.mj_forward(m, d)
    out = {"tip": float(np.abs(cm.master_tip(m, d) - master_model.fk(master, q1)).max())}
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, None, cm.master_site_id)
    out["jacobian"] = float(np.abs(jacp[[0, 2]][:, da] - master_model.jacobian(master, q1)).max())
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    out["mass"] = float(np.abs(M[np.ix_(da, da)] - master_model.mass_matrix(master, q1)).max())
    out["gravity"] = float(np.abs(d.qfrc_bias[da] - master_model.gravity_force(master, q1)).max())
    d.qvel[da] = dq1
    mujoco.mj_forward(m, d)
    friction = np.asarray(master.damping) * dq1
    out["bias"] = float(np.abs(d.qfrc_bias[da] - (master_model.nle(master, q1, dq1) - friction)).max())
    return out


@dataclass
class FidelityTable:
    """Result of ``fidelity_study``: per N the maximum relative error of each quantity."""

    Ns: tuple[int, ...]
    errors: dict[str, np.ndarray]  # quantity -> (len(Ns),)
    orders: dict[str, np.ndarray]  # quantity -> (len(Ns) - 1,) observed order between successive Ns
    master: dict[str, float]  # max absolute master errors
    n_samples: int
    seed: int
    meta: dict = field(default_factory=dict)

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
        head = "| N | " + " | ".join(f"{q} | order" for q in QUANTITIES) + " |"
        sep = "|---:|" + "---:|---:|" * len(QUANTITIES)
        lines = [head, sep]
        for r in self.rows():
            cells = [str(r["N"])]
            for q in QUANTITIES:
                o = r[f"{q}_order"]
                # an order between two values at rounding level (the elastic force is exact) means nothing
                exact = r[q] < ROUNDING_LEVEL
                cells += [f"{r[q]:.3e}", "" if np.isnan(o) else ("exact" if exact else f"{o:.2f}")]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
        lines.append(f"max over {self.n_samples} random in-range q2 (seed {self.seed}); " + "; ".join(
            f"{q}: {QUANTITY_TEXT[q]}" for q in QUANTITIES))
        lines.append("master vs analytic (max abs): "
                     + ", ".join(f"{k} {v:.1e}" for k, v in self.master.items()))
        return "\n".join(lines)

    def write_csv(self, path) -> Path:
        return write_rows_csv(self.rows(), path)

    def write_markdown(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return write_atomic(path, self.to_markdown() + "\n")


def observed_orders(Ns, errs) -> np.ndarray:
    """log(err_k / err_{k+1}) / log(N_{k+1} / N_k) for successive entries (nan where undefined)."""
    Ns = np.asarray(Ns, float)
    errs = np.asarray(errs, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(errs[:-1] / errs[1:]) / np.log(Ns[1:] / Ns[:-1])


def fidelity_study(Ns=(4, 8, 16, 32), n_samples: int = 20, seed: int = 0,
                   master: MasterParams | None = None, slave: SlaveParams | None = None,
                   plant: PlantConfig | None = None) -> FidelityTable:
    """Compare MuJoCo models with N segments per section against the analytic models (see module doc).

    plant: template config (actuation, armature_fraction, ...); its ``segments`` is replaced by each N.
    """
    master = MasterParams() if master is None else master
    slave = SlaveParams() if slave is None else slave
    plant = PlantConfig() if plant is None else plant
    Ns = tuple(int(n) for n in Ns)
    q2s = sample_q2(slave, n_samples, seed)
    errors = {q: np.zeros(len(Ns)) for q in QUANTITIES}
    master_err: dict[str, float] = {}
    rng = np.random.default_rng(seed + 1)
    for k, N in enumerate(Ns):
        m, cm = build_model(master, slave, _with_segments(plant, N))
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
                         seed=seed, meta={"actuation": plant.actuation,
                                          "armature_fraction": plant.armature_fraction})


def _with_segments(plant: PlantConfig, N: int) -> PlantConfig:
    from dataclasses import replace

    return replace(plant, segments=int(N))


def plot_fidelity(table: FidelityTable, path) -> Path:
    """Log-log plot of the relative errors vs N with an N^-2 guide; saved to ``path`` (png/pdf/svg)."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Ns = np.asarray(table.Ns, float)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for q in QUANTITIES:
        e = table.errors[q]
        if np.all(e > 0):
            ax.loglog(Ns, e, "o-", label=QUANTITY_TEXT[q])
    ref = table.errors["mass"][0] if table.errors["mass"][0] > 0 else 1e-2
    ax.loglog(Ns, ref * (Ns / Ns[0]) ** -2, "k--", lw=0.8, label="$N^{-2}$")
    ax.loglog(Ns, ref * (Ns / Ns[0]) ** -1, "k:", lw=0.8, label="$N^{-1}$")
    ax.set_xticks(Ns)
    ax.set_xticklabels([str(int(n)) for n in Ns])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("segments per section N")
    ax.set_ylabel("max relative error")
    ax.set_title("MuJoCo Octarm vs analytic CC model")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        return write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=120, format=path.suffix[1:] or "png"))
    finally:
        plt.close(fig)


CC_COLUMNS = ("N", "enforce_cc", "us_per_step", "tip_dev_mm", "hinge_dev_mrad", "closed_loop")


def _held_bend(m: mujoco.MjModel, cm: ChainMap, slave: SlaveParams, q2: np.ndarray,
               settle_steps: int) -> tuple[float, float, np.ndarray]:
    """Servos hold q2 under gravity (static feed-forward + elastic correction every step): returns
    (tip departure from the CC chain at the sensed q2 (m), largest hinge departure (rad), the command
    log (settle_steps, nu + nv) of constant held commands for timing)."""
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
    tip = cm.octarm_tip(m, d)
    d_cc = mujoco.MjData(m)
    cm.set_q2(d_cc, q2_s)
    mujoco.mj_kinematics(m, d_cc)
    hinge = np.asarray(cm.is_hinge) == 1
    resid = (q - cm.joints_from_q2(q2_s))[hinge]
    if not (np.all(np.isfinite(q)) and warning_count(d) == 0):
        return float("nan"), float("nan"), log
    return float(np.linalg.norm(tip - cm.octarm_tip(m, d_cc))), float(np.abs(resid).max()), log


def cc_study(Ns=(4, 8, 16, 32), n_samples: int = 4, seed: int = 0, settle_steps: int = 1500,
             loop_duration: float = 2.0, master: MasterParams | None = None, slave: SlaveParams | None = None,
             plant: PlantConfig | None = None) -> list[dict]:
    """Constrained vs free chain (see module docstring), servo actuation.  Rows (one per N and
    enforce_cc): N, enforce_cc, us_per_step (best of 3 compiled replays of the held commands),
    tip_dev_mm and hinge_dev_mrad (max over n_samples bent q2; nan if the hold went unstable),
    closed_loop (status of the paper scenario on that plant for loop_duration s, with the time if it
    diverged)."""
    from dataclasses import replace

    from harness.config.scenario import Scenario
    from harness.loop.fast import K
    from harness.loop.mujoco_loop import simulate_mujoco
    from harness.loop.native import MJ_FUNCS

    master = MasterParams() if master is None else master
    slave = SlaveParams() if slave is None else slave
    plant = PlantConfig() if plant is None else plant
    q2s = sample_q2(slave, n_samples, seed)
    rows = []
    for N in Ns:
        for cc in (True, False):
            p = replace(plant, segments=int(N), enforce_cc=cc, actuation="servo")
            m, cm = build_model(master, slave, p)
            tip_dev = hinge_dev = 0.0
            log = None
            for q2 in q2s:
                t, h, log = _held_bend(m, cm, slave, q2, settle_steps)
                tip_dev, hinge_dev = max(tip_dev, t), max(hinge_dev, h)  # nan propagates
                if not np.isfinite(t):
                    tip_dev = hinge_dev = float("nan")
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
    lines = ["| N | CC enforced | mj_step (us) | tip off the CC shape (mm) | hinge off CC (mrad) | "
             f"closed loop, paper scenario {loop_duration:g} s |", "|---:|:---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['N']} | {'yes' if r['enforce_cc'] else 'no'} | {r['us_per_step']:.1f} | "
                     f"{r['tip_dev_mm']:.3f} | {r['hinge_dev_mrad']:.2f} | {r['closed_loop']} |")
    lines.append("")
    lines.append(f"servos holding {n_samples} random bent q2 under gravity for {settle_steps} steps "
                 "(static feed-forward + elastic correction); max over the samples; mj_step = compiled "
                 "replay of the held commands, best of 3.")
    return "\n".join(lines)


def write_rows_csv(rows: list[dict], path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp: Path) -> None:
        with tmp.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)

    return write_atomic(path, write)


def main_fidelity(segments, out, progress: bool = True, samples: int = 50, seed: int = 0,
                  cc_samples: int = 4) -> int:
    """`teleop fidelity`: the discretization table (fidelity.md/.csv/.png) and the constant-curvature
    study (fidelity_cc.md/.csv) for the given segment counts, printed and written into `out`."""
    import sys

    out = Path(out)
    say = (lambda msg: print(msg, file=sys.stderr, flush=True)) if progress else (lambda msg: None)
    say(f"discretization errors at {samples} random q2 for N = {', '.join(map(str, segments))} ...")
    table = fidelity_study(Ns=tuple(segments), n_samples=samples, seed=seed)
    written = [table.write_markdown(out / "fidelity.md"), table.write_csv(out / "fidelity.csv"),
               plot_fidelity(table, out / "fidelity.png")]
    print(table.to_markdown())
    say("worst-case tip error by optimization (corners + random starts + Nelder-Mead) ...")
    worst = worst_case_markdown(segments, seed)
    (out / "fidelity_worst.md").write_text(worst + "\n")
    written.append(out / "fidelity_worst.md")
    print()
    print(worst)
    say("constant curvature enforced vs free chain (held bends, mj_step cost, closed loop) ...")
    settle, loop = 1500, 2.0
    rows = cc_study(Ns=tuple(segments), n_samples=cc_samples, seed=seed, settle_steps=settle,
                    loop_duration=loop)
    text = cc_markdown(rows, cc_samples, settle, loop)
    write_atomic(out / "fidelity_cc.md", text + "\n")
    written += [out / "fidelity_cc.md", write_rows_csv(rows, out / "fidelity_cc.csv")]
    print()
    print(text)
    print(f"outputs in {out}/: " + ", ".join(Path(p).name for p in written))
    return 0


def worst_case_markdown(segments, seed: int = 0) -> str:
    """Table of the worst-case relative tip error over the in-range q2 box, by optimization
    (`fidelity_reference.worst_tip_error`), for each N: error, in mm of sum(L0), and the q2."""
    from harness.studies.fidelity_reference import worst_tip_error

    slave = SlaveParams()
    L = float(np.sum(slave.rest_lengths))
    lines = ["| N | worst tip error (rel.) | mm | at d (m) | at k d (rad) |", "|---:|---:|---:|---|---|"]
    for N in segments:
        e, q = worst_tip_error(int(N), slave, seed=seed)
        lines.append(f"| {int(N)} | {e:.3e} | {e * L * 1e3:.2f} | {np.round(q[:3], 3).tolist()} | "
                     f"{np.round(q[3:] * q[:3], 3).tolist()} |")
    return "\n".join(lines)


def warning_count(d: mujoco.MjData) -> int:
    """Total number of MuJoCo warnings of every kind recorded in d."""
    return int(sum(d.warning[int(w)].number for name, w in mujoco.mjtWarning.__members__.items()
                   if name != "mjNWARNING"))


__all__ = ["QUANTITIES", "FidelityTable", "cc_study", "fidelity_study", "main_fidelity", "master_errors",
           "observed_orders", "plot_fidelity", "q2_scales", "sample_q2", "slave_errors",
           "warning_count", "worst_case_markdown"]
