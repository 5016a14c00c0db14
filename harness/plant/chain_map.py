"""The discretized Octarm chain <-> CC coordinates q2 (joints = C [d - L0, k d], R C = I): numba-
compatible ``chain_*`` kernels writing into ``out``, and ``ChainMap``, a model's addresses and arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np

from controllers.scratch import scratch, scratch_zeros


def chain_joints_from_q2(q2, C, L0, out):
    """CC manifold -> chain joints: out (n_chain,) = C u, u = [d - L0, k d] (m, rad); q2 (6,), C (n_chain, 6),
    L0 (3,)."""
    n = C.shape[0]
    u = scratch(6)
    for i in range(3):
        u[i] = q2[i] - L0[i]
        u[3 + i] = q2[3 + i] * q2[i]
    for r in range(n):
        acc = 0.0
        for c in range(6):
            acc += C[r, c] * u[c]
        out[r] = acc


def chain_joints_rate_add(q2, dq2, C, scale, out):
    """out (n_chain,) += scale (n_chain,) * A(q2) dq2 (joint rates of a CC motion; A: `ChainMap.jacobian`)."""
    n = C.shape[0]
    for r in range(n):
        v = 0.0
        for i in range(3):
            v += (C[r, i] + q2[3 + i] * C[r, 3 + i]) * dq2[i] + (q2[i] * C[r, 3 + i]) * dq2[3 + i]
        out[r] += scale[r] * v


def chain_sense(qpos_chain, qvel_chain, R, L0, q2, dq2):
    """Sensed q2, dq2 (6,) from chain joint positions and velocities (n_chain,): d_i = L0_i + (R qpos)_i
    (least-squares fit of the slide extensions), k_i = (R qpos)_{3+i} / d_i (section i's hinge sum over
    d_i; exact on the manifold), dd_i = (R qvel)_i, dk_i = ((R qvel)_{3+i} - k_i dd_i) / d_i."""
    n = R.shape[1]
    for i in range(3):
        e = th = de = dth = 0.0
        for c in range(n):
            e += R[i, c] * qpos_chain[c]
            th += R[3 + i, c] * qpos_chain[c]
            de += R[i, c] * qvel_chain[c]
            dth += R[3 + i, c] * qvel_chain[c]
        d = L0[i] + e
        k = th / d
        q2[i], q2[3 + i] = d, k
        dq2[i], dq2[3 + i] = de, (dth - k * de) / d


def chain_force_from_T2(q2, T2, R, out):
    """Virtual-work map of T2 = [F_d (N), M_k (N m^2)] onto the chain joints, out (n_chain,) = B^T T2 with
    B = d q2_sensed / d qpos_chain, so A^T out = T2 on the CC manifold and out . qvel = T2 . dq2_sensed:
    each hinge of section i gets M_k_i / d_i, the slides R[:3]^T of F_d_i - k_i M_k_i / d_i."""
    n = R.shape[1]
    w = scratch(6)
    for i in range(3):
        mk = T2[3 + i] / q2[i]
        w[i], w[3 + i] = T2[i] - q2[3 + i] * mk, mk
    for c in range(n):
        acc = 0.0
        for r in range(6):
            acc += R[r, c] * w[r]
        out[c] = acc


def muscle_commands(q2, T2, radius, max_force, out):
    """Commands out (6,) = [p+_1, p-_1, p+_2, ...] (N) of the muscle groups at offsets s = +r, -r (radius
    (3,), m) that realize T2 (6,) at q2 (6,); returns how many lie outside [0, max_force] (MuJoCo clips
    them: saturated groups).  A group at offset s pushes along a fibre l_s = d (1 - s k), so the pair
    realizes [F_d, M_k] by p+ = F_d/2 - (1 + r k) M_k / (2 r d), p- = F_d/2 + (1 - r k) M_k / (2 r d)."""
    n_sat = 0
    for i in range(3):
        d, k, r = q2[i], q2[3 + i], radius[i]
        m = T2[3 + i] / (2.0 * r * d)
        pp = 0.5 * T2[i] - (1.0 + r * k) * m
        pm = 0.5 * T2[i] + (1.0 - r * k) * m
        out[2 * i], out[2 * i + 1] = pp, pm
        if pp < 0.0 or pp > max_force[i]:
            n_sat += 1
        if pm < 0.0 or pm > max_force[i]:
            n_sat += 1
    return n_sat


def chain_elastic_correction(qpos_chain, R, C, L0, section, is_hinge, seg_kb, ke, k_joint, k_shape, out):
    """Force out (n_chain,) to ADD to MuJoCo's joint springs so that springs + out = -grad E, E = sum_i
    [seg_kb_i / (2 d_i) sum_j theta_ij^2 + ke_i (d_i - L0_i)^2 / 2] + sum_s k_shape_s r_s^2 / 2 (d_i = L0_i
    + (R qpos)_i, theta_ij section i's hinges, r = s - C_e (P s) the non-CC part of the slides s, P = R[:3]);
    the analytic elastic energy on the manifold.  seg_kb = N Kb; k_joint: MuJoCo's; k_shape 0 on hinges."""
    n = R.shape[1]
    e, sq = scratch_zeros(3), scratch_zeros(3)
    for c in range(n):
        q = qpos_chain[c]
        for i in range(3):
            e[i] += R[i, c] * q
        if is_hinge[c] == 1:
            sq[section[c]] += q * q
    dEdd, dinv = scratch(3), scratch(3)
    for i in range(3):
        d = L0[i] + e[i]
        dinv[i] = 1.0 / d
        dEdd[i] = -0.5 * seg_kb[i] * sq[i] * dinv[i] * dinv[i] + ke[i] * e[i]
    # shape term: g = k_shape * r on slides;  grad = g - P^T (C_e^T g)
    ctg = scratch_zeros(3)
    for c in range(n):
        if is_hinge[c] == 0:
            r = qpos_chain[c]
            for i in range(3):
                r -= C[c, i] * e[i]
            out[c] = k_shape[c] * r  # g, kept in out until the last loop
            if k_shape[c] != 0.0:
                for i in range(3):
                    ctg[i] += C[c, i] * out[c]
    for c in range(n):
        q = qpos_chain[c]
        if is_hinge[c] == 1:
            grad = seg_kb[section[c]] * q * dinv[section[c]]
        else:
            grad = out[c]
            for i in range(3):
                grad += R[i, c] * (dEdd[i] - ctg[i])
        out[c] = -grad + k_joint[c] * q


def chain_layout(n_segments: int) -> dict[str, np.ndarray]:
    """Constant layout arrays for N segments per section: ``C`` (n_chain, 6), ``R`` (6, n_chain) (R C = I),
    ``section``, ``is_hinge``, ``segment`` (n_chain,) int64 (segment N for the tip slide)."""
    N = int(n_segments)
    n = 6 * N + 1
    section = np.r_[np.repeat(np.arange(3), 2 * N), 2].astype(np.int64)
    segment = np.r_[np.tile(np.repeat(np.arange(N), 2), 3), N].astype(np.int64)
    is_hinge = np.r_[np.tile([0, 1], 3 * N), 0].astype(np.int64)
    C = np.zeros((n, 6))
    for c in range(n - 1):
        i, j = section[c], segment[c]
        if is_hinge[c]:
            C[c, 3 + i] = 1.0 / N
        elif j == 0:  # the rod from the previous section's last midpoint (or the base)
            C[c, i] = 0.5 / N
            if i > 0:
                C[c, i - 1] = 0.5 / N
        else:
            C[c, i] = 1.0 / N
    C[n - 1, 2] = 0.5 / N  # tip slide
    slides = np.flatnonzero(is_hinge == 0)
    R = np.zeros((6, n))
    R[:3, slides] = np.linalg.pinv(C[slides, :3])  # least-squares extensions of the slides
    for c in np.flatnonzero(is_hinge == 1):
        R[3 + section[c], c] = 1.0
    return {"C": C, "R": R, "section": section, "is_hinge": is_hinge, "segment": segment}


@dataclass(frozen=True, eq=False)
class ChainMap:
    """Addresses and constant arrays tying a MuJoCo model to q2 (read-only); chain arrays (6N + 1,) in
    MuJoCo order; muscle_actuator_ids in ``muscle_commands`` order (empty unless muscle, as
    chain_actuator_ids for muscles); *_base_pos (3,) world; C, R, L0: ``chain_layout``."""

    n_segments: int
    actuation: str
    enforce_cc: bool
    master_qpos_adr: np.ndarray
    master_dof_adr: np.ndarray
    master_actuator_ids: np.ndarray
    chain_qpos_adr: np.ndarray
    chain_dof_adr: np.ndarray
    chain_actuator_ids: np.ndarray
    muscle_actuator_ids: np.ndarray
    muscle_radius: np.ndarray
    muscle_max_force: np.ndarray
    master_site_id: int
    tip_site_id: int
    master_base_pos: np.ndarray
    octarm_base_pos: np.ndarray
    C: np.ndarray
    R: np.ndarray
    L0: np.ndarray
    section: np.ndarray
    is_hinge: np.ndarray
    segment: np.ndarray
    joint_stiffness: np.ndarray
    shape_stiffness: np.ndarray
    seg_kb: np.ndarray
    ke: np.ndarray
    servo_kp: np.ndarray
    servo_kv: np.ndarray

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.type == "np.ndarray":
                integer = f.name.endswith(("_adr", "_ids")) or f.name in ("section", "is_hinge", "segment")
                a = np.array(getattr(self, f.name), dtype=np.int64 if integer else np.float64, order="C")
                a.setflags(write=False)
                object.__setattr__(self, f.name, a)

    @property
    def n_chain(self) -> int:
        return int(self.C.shape[0])

    @property
    def elastic_args(self) -> tuple:
        """Constant arguments of ``chain_elastic_correction`` after ``qpos_chain`` (and before ``out``)."""
        return (self.R, self.C, self.L0, self.section, self.is_hinge, self.seg_kb, self.ke,
                self.joint_stiffness, self.shape_stiffness)

    def joints_from_q2(self, q2) -> np.ndarray:
        """(n_chain,) chain joint positions on the CC manifold for q2 (6,)."""
        out = np.empty(self.n_chain)
        chain_joints_from_q2(np.asarray(q2, dtype=float), self.C, self.L0, out)
        return out

    def jacobian(self, q2) -> np.ndarray:
        """A(q2) = d joints / d q2 (n_chain, 6): columns C[:, i] + k_i C[:, 3+i] and d_i C[:, 3+i]."""
        q2 = np.asarray(q2, dtype=float)
        return np.hstack([self.C[:, :3] + q2[3:] * self.C[:, 3:], q2[:3] * self.C[:, 3:]])

    def q2_from_joints(self, qpos_chain) -> np.ndarray:
        """Sensed q2 (6,) from chain joint positions (n_chain,)."""
        return self.sense_joints(qpos_chain, np.zeros(self.n_chain))[0]

    def sense_joints(self, qpos_chain, qvel_chain) -> tuple[np.ndarray, np.ndarray]:
        """Sensed (q2, dq2) (6,) each from chain joint positions and velocities (n_chain,)."""
        q2, dq2 = np.empty(6), np.empty(6)
        chain_sense(np.asarray(qpos_chain, dtype=float), np.asarray(qvel_chain, dtype=float), self.R, self.L0,
                    q2, dq2)
        return q2, dq2

    def force_from_T2(self, q2, T2) -> np.ndarray:
        """Chain joint forces (n_chain,) with A(q2)^T tau = T2 (see ``chain_force_from_T2``)."""
        out = np.empty(self.n_chain)
        chain_force_from_T2(np.asarray(q2, dtype=float), np.asarray(T2, dtype=float), self.R, out)
        return out

    def muscle_commands(self, q2, T2) -> tuple[np.ndarray, int]:
        """Muscle group commands (6,) for T2 at q2 and the number of saturated groups."""
        out = np.empty(6)
        n_sat = muscle_commands(np.asarray(q2, dtype=float), np.asarray(T2, dtype=float),
                                self.muscle_radius, self.muscle_max_force, out)
        return out, int(n_sat)

    def elastic_correction(self, qpos_chain) -> np.ndarray:
        """Force (n_chain,) to add to MuJoCo's springs (see ``chain_elastic_correction``)."""
        out = np.empty(self.n_chain)
        chain_elastic_correction(np.asarray(qpos_chain, dtype=float), *self.elastic_args, out)
        return out

    def chain_qpos(self, d: mujoco.MjData) -> np.ndarray:
        return d.qpos[self.chain_qpos_adr].copy()

    def set_q2(self, d: mujoco.MjData, q2, dq2=None) -> None:
        """Put the chain on the CC manifold at q2 (and velocity A dq2; zero if None)."""
        d.qpos[self.chain_qpos_adr] = self.joints_from_q2(q2)
        d.qvel[self.chain_dof_adr] = 0.0 if dq2 is None else self.jacobian(q2) @ np.asarray(dq2, float)

    def sense(self, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(q2, dq2) sensed from the chain joints of d."""
        return self.sense_joints(self.chain_qpos(d), d.qvel[self.chain_dof_adr])

    def master_tip(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """[X, Z] of master_tip_site relative to master_base (needs up-to-date kinematics)."""
        return (d.site_xpos[self.master_site_id] - self.master_base_pos)[[0, 2]]

    def octarm_tip(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """[X, Z] of octarm_tip_site relative to octarm_base (needs up-to-date kinematics)."""
        return (d.site_xpos[self.tip_site_id] - self.octarm_base_pos)[[0, 2]]


# kernels compiled by harness.loop.fast (numba) together with controllers/
KERNELS = ("chain_joints_from_q2", "chain_joints_rate_add", "chain_sense",
           "chain_force_from_T2", "muscle_commands", "chain_elastic_correction")
