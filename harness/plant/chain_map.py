"""The discretized Octarm chain <-> CC coordinates q2: sensing, actuation and elastic-correction maps.

The joint layout and the CC manifold (joints = C [d - L0, k d], [d - L0, k d] = R joints) are
described in `harness.plant.mujoco_model`.  The per-step functions ``chain_*`` below are plain loops
over float64/int64 arrays (no Python objects, no np.dot/np.linalg) so they can be compiled with numba
from the harness' step kernel (`harness.loop.fast`); each writes into an ``out`` array.  ``ChainMap``
holds the model's addresses and constant maps, with allocating wrappers for interactive use.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np

from controllers.scratch import scratch, scratch_zeros

# ================================================================================================
# Numba-compatible per-step kernels (plain loops, float64/int64 arrays in, results written to `out`)
# ================================================================================================

def chain_joints_from_q2(q2, C, L0, out):
    """CC manifold -> chain joints.  q2 (6,) = [d (m), k (1/m)]; C (n_chain, 6); L0 (3,); out (n_chain,).

    out = C u with u = [d - L0, k * d] (extensions in m, section bends in rad).
    """
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


def chain_joints_jacobian(q2, C, out):
    """A(q2) = d qpos_chain / d q2, out (n_chain, 6) (columns d1..d3 in 1, k1..k3 in m).

    A[:, i] = C[:, i] + k_i C[:, 3+i],  A[:, 3+i] = d_i C[:, 3+i]  (from u = [d - L0, k d]).
    """
    n = C.shape[0]
    for r in range(n):
        for i in range(3):
            out[r, i] = C[r, i] + q2[3 + i] * C[r, 3 + i]
            out[r, 3 + i] = q2[i] * C[r, 3 + i]


def chain_joints_rate_add(q2, dq2, C, scale, out):
    """out (n_chain,) += scale (n_chain,) * A(q2) dq2, the joint rates of a CC motion, without forming A
    (columns as in ``chain_joints_jacobian``: C[:, i] + k_i C[:, 3+i] and d_i C[:, 3+i])."""
    n = C.shape[0]
    for r in range(n):
        v = 0.0
        for i in range(3):
            v += (C[r, i] + q2[3 + i] * C[r, 3 + i]) * dq2[i] + (q2[i] * C[r, 3 + i]) * dq2[3 + i]
        out[r] += scale[r] * v


def chain_q2_from_joints(qpos_chain, R, L0, out):
    """Sense q2 (6,) from chain joints (n_chain,).  R (6, n_chain): u = R qpos_chain; L0 (3,).

    d_i = L0_i + (least-squares fit of the slide extensions, rows 0..2 of R = pinv(S)),
    k_i = (sum of section i's hinge angles, rows 3..5 of R) / d_i.  Exact on the CC manifold (R C = I).
    """
    n = R.shape[1]
    for i in range(3):
        e = 0.0
        th = 0.0
        for c in range(n):
            e += R[i, c] * qpos_chain[c]
            th += R[3 + i, c] * qpos_chain[c]
        d = L0[i] + e
        out[i] = d
        out[3 + i] = th / d


def chain_sense(qpos_chain, qvel_chain, R, L0, q2, dq2):
    """Sense q2 (6,) and dq2/dt (6,) [m/s, 1/(m s)] from chain joint positions and velocities
    (n_chain,) in one pass over R: q2 as in ``chain_q2_from_joints`` (the same sums, identical
    numbers), dd_i = (R du)_i, dk_i = (dTheta_i - k_i dd_i) / d_i with du = R qvel_chain.
    """
    n = R.shape[1]
    for i in range(3):
        e = 0.0
        th = 0.0
        de = 0.0
        dth = 0.0
        for c in range(n):
            e += R[i, c] * qpos_chain[c]
            th += R[3 + i, c] * qpos_chain[c]
            de += R[i, c] * qvel_chain[c]
            dth += R[3 + i, c] * qvel_chain[c]
        d = L0[i] + e
        k = th / d
        q2[i] = d
        q2[3 + i] = k
        dq2[i] = de
        dq2[3 + i] = (dth - k * de) / d


def chain_force_from_T2(q2, T2, R, out):
    """Virtual-work map of T2 = [F_d1..3 (N), M_k1..3 (N m^2)] onto the chain joints, out (n_chain,).

    tau = B^T T2 with B = d q2_sensed / d qpos_chain (the transpose of the velocity sensing map), so
    A(q2)^T tau = (B A)^T T2 = T2 exactly on the CC manifold (B A = I), and tau . qvel = T2 . dq2_sensed
    everywhere.  Written out for this layout:
      * every hinge of section i gets the same torque  M_k_i / d_i  (N m);
      * with G_i = F_d_i - k_i M_k_i / d_i (the part of F_d not produced by the hinge torques through
        d theta / d d_i = k_i / N) and y = (S^T S)^-1 G, every interior slide (j >= 1) of section i gets
        y_i / N, the boundary slide (i, 0) gets (y_{i-1} + y_i) / (2N) (y_{-1} = 0), the tip slide
        y_2 / (2N): the minimum-norm slide forces (P^T G, P = pinv(S)), equal within a section.
    q2 is the state at which the map is evaluated (normally the sensed q2).
    """
    n = R.shape[1]
    w = scratch(6)
    for i in range(3):
        d = q2[i]
        mk = T2[3 + i] / d
        w[3 + i] = mk
        w[i] = T2[i] - q2[3 + i] * mk
    for c in range(n):
        acc = 0.0
        for r in range(6):
            acc += R[r, c] * w[r]
        out[c] = acc


def muscle_commands(q2, T2, radius, max_force, out):
    """Force commands of the antagonistic muscle groups that realize T2 on the CC model; returns how many
    of the 6 commands lie outside [0, F_max] (MuJoCo clips those: saturated groups).

    q2 (6,) = [d (m), k (1/m)], normally the sensed q2; T2 (6,) = [F_d1..3 (N), M_k1..3 (N m^2)], the
    generalized forces of the controller (paper (17)); radius (3,) = r_i (m), the lateral offsets of
    the groups; max_force (3,) = F_max,i (N); out (6,) = [p+_1, p-_1, p+_2, p-_2, p+_3, p-_3] (N), the
    group at s = +r then the one at s = -r of each section (the order of ChainMap.muscle_actuator_ids).

    A group at offset s pushes along a fibre of length l_s = d (1 - s k) (extensor: force p >= 0
    lengthens it), so its generalized force on (d_i, k_i) is p (dl_s/dd, dl_s/dk) = p (1 - s k, -s d).
    The pair realizes [F_d, M_k] when A p = T with A = [[1 - r k, 1 + r k], [-r d, r d]], det A = 2 r d:
      p+ = F_d / 2 - (1 + r k) M_k / (2 r d),    p- = F_d / 2 + (1 - r k) M_k / (2 r d).
    The commands are written unclipped: the muscle actuators are ctrllimited to [0, F_max], so MuJoCo
    clips them (a group cannot pull, nor push past F_max), and each section's actuator state follows
    the clipped command with the time constant tau.  What the loop must do at each control step, with
    the same sensed q2 and T2 as the torque mode's ``chain_force_from_T2``:
      n_sat = muscle_commands(q2s, T2, radius, max_force, out);  ctrl[muscle_actuator_ids] = out
    (held over the control period; n_sat, summed over the run, counts saturated group-steps).
    """
    n_sat = 0
    for i in range(3):
        d = q2[i]
        k = q2[3 + i]
        r = radius[i]
        m = T2[3 + i] / (2.0 * r * d)
        pp = 0.5 * T2[i] - (1.0 + r * k) * m
        pm = 0.5 * T2[i] + (1.0 - r * k) * m
        out[2 * i] = pp
        out[2 * i + 1] = pm
        if pp < 0.0 or pp > max_force[i]:
            n_sat += 1
        if pm < 0.0 or pm > max_force[i]:
            n_sat += 1
    return n_sat


def chain_extension(qpos_chain, R, section, is_hinge, e, sq):
    """Section extensions e (3,) = R[:3] qpos_chain (m) and, per section, the sum of its squared hinge
    angles sq (3,) (rad^2): what the chain's elastic energy and its gradient are built from."""
    e[:] = 0.0
    sq[:] = 0.0
    for c in range(R.shape[1]):
        q = qpos_chain[c]
        for i in range(3):
            e[i] += R[i, c] * q
        if is_hinge[c] == 1:
            sq[section[c]] += q * q


def chain_elastic_correction(qpos_chain, R, C, L0, section, is_hinge, seg_kb, ke, k_joint, k_shape, out):
    """Generalized elastic force to ADD (through qfrc_applied) to MuJoCo's own joint springs, out (n_chain,).

    Result = -grad E(qpos_chain) - (-k_joint * qpos_chain), so that springs + correction = -grad E with
      E = sum_i [ seg_kb_i / (2 d_i) sum_j theta_ij^2 + 1/2 ke_i (d_i - L0_i)^2 ] + E_shape,
      E_shape = 1/2 sum_slides k_shape_s r_s^2,   r = s - C_e (P s)  (the non-CC part of the slides),
    d_i = L0_i + (P s)_i sensed as in ``chain_q2_from_joints`` (P = rows 0..2 of R = pinv(S)), theta_ij
    the hinges of section i, seg_kb_i = N Kb_i (N m^2), ke_i = Ke_i (N/m), s the slides.  On the CC
    manifold E equals the analytic sum_i 1/2 Kb_i d_i k_i^2 + 1/2 Ke_i (d_i - L0_i)^2, so
    A^T (springs + correction) = -dV_elastic/dq2 exactly.

    E_shape vanishes with its gradient on the manifold (C_e P projects onto it): it keeps the non-CC
    slide patterns (e.g. one segment stretched, its neighbour compressed) as stiff as MuJoCo's local
    springs (``build_model`` sets k_shape = the slide stiffness); the sensed-length energy alone would
    leave those 3N - 2 patterns without any stiffness.  k_shape = 0 gives exactly the brief's energy.

    The correction is a stiff state-dependent force (its linearization has rates of a few hundred
    rad/s, from the length dependence of the bending stiffness): recompute it at every physics step.
    Holding it over several 1 ms steps (zero-order hold) was measured to destabilize N = 1..8.

    Arrays: qpos_chain (n,); R (6, n); C (n, 6); L0 (3,); section (n,) int64 in 0..2 (2 for the tip);
    is_hinge (n,) int64 (1 hinge, 0 slide); seg_kb, ke (3,); k_joint (n,) MuJoCo joint stiffness
    (springref 0); k_shape (n,) (0 on hinges); out (n,).
    """
    n = R.shape[1]
    e = scratch(3)
    sq = scratch(3)
    chain_extension(qpos_chain, R, section, is_hinge, e, sq)
    dEdd = scratch(3)
    dinv = scratch(3)
    for i in range(3):
        d = L0[i] + e[i]
        dinv[i] = 1.0 / d
        dEdd[i] = -0.5 * seg_kb[i] * sq[i] * dinv[i] * dinv[i] + ke[i] * e[i]
    # shape term: g = k_shape * r on slides;  grad = g - P^T (C_e^T g)
    ctg = scratch_zeros(3)
    for c in range(n):
        if is_hinge[c] == 0 and k_shape[c] != 0.0:
            r = qpos_chain[c]
            for i in range(3):
                r -= C[c, i] * e[i]
            g = k_shape[c] * r
            for i in range(3):
                ctg[i] += C[c, i] * g
    for c in range(n):
        q = qpos_chain[c]
        if is_hinge[c] == 1:
            grad = seg_kb[section[c]] * q * dinv[section[c]]
        else:
            r = q
            for i in range(3):
                r -= C[c, i] * e[i]
            grad = k_shape[c] * r
            for i in range(3):
                grad += R[i, c] * (dEdd[i] - ctg[i])
        out[c] = -grad + k_joint[c] * q


def chain_elastic_energy(qpos_chain, R, C, L0, section, is_hinge, seg_kb, ke, k_shape):
    """The energy E (J) whose negative gradient ``chain_elastic_correction`` completes (see there)."""
    n = R.shape[1]
    e = scratch(3)
    sq = scratch(3)
    chain_extension(qpos_chain, R, section, is_hinge, e, sq)
    E = 0.0
    for i in range(3):
        E += 0.5 * seg_kb[i] * sq[i] / (L0[i] + e[i]) + 0.5 * ke[i] * e[i] * e[i]
    for c in range(n):
        if is_hinge[c] == 0:
            r = qpos_chain[c]
            for i in range(3):
                r -= C[c, i] * e[i]
            E += 0.5 * k_shape[c] * r * r
    return E


# ================================================================================================
# Constant matrices of the layout
# ================================================================================================

def chain_layout(n_segments: int) -> dict[str, np.ndarray]:
    """Constant layout arrays for N segments per section (no MuJoCo needed).

    Returns dict with ``C`` (n_chain, 6), ``R`` (6, n_chain), ``S`` (n_slides, 3) (extensions e -> slides),
    ``section`` and ``is_hinge`` (n_chain,) int64, ``slide_index`` (n_slides,) chain indices of the slides,
    ``segment`` (n_chain,) segment index j (N for the tip slide).  R C = I_6.
    """
    N = int(n_segments)
    n = 6 * N + 1
    C = np.zeros((n, 6))
    section = np.zeros(n, dtype=np.int64)
    is_hinge = np.zeros(n, dtype=np.int64)
    segment = np.zeros(n, dtype=np.int64)
    c = 0
    for i in range(3):
        for j in range(N):
            # slide (i, j)
            if j == 0:
                C[c, i] = 0.5 / N
                if i > 0:
                    C[c, i - 1] = 0.5 / N
            else:
                C[c, i] = 1.0 / N
            section[c], segment[c] = i, j
            c += 1
            # hinge (i, j)
            C[c, 3 + i] = 1.0 / N
            section[c], segment[c], is_hinge[c] = i, j, 1
            c += 1
    C[c, 2] = 0.5 / N  # tip slide
    section[c], segment[c] = 2, N
    slide_index = np.flatnonzero(is_hinge == 0)
    S = C[slide_index, :3].copy()
    P = np.linalg.pinv(S)  # (3, n_slides), P S = I
    R = np.zeros((6, n))
    R[:3, slide_index] = P
    for c in np.flatnonzero(is_hinge == 1):
        R[3 + section[c], c] = 1.0
    return {"C": C, "R": R, "S": S, "section": section, "is_hinge": is_hinge,
            "slide_index": slide_index, "segment": segment}


# ================================================================================================
# ChainMap
# ================================================================================================

def _ro(a, dtype=np.float64) -> np.ndarray:
    a = np.ascontiguousarray(np.array(a, dtype=dtype))
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class ChainMap:
    """Addresses and constant arrays tying the MuJoCo model to the 6 CC coordinates q2.

    All arrays are read-only, float64 or int64, C-contiguous (ready for numba kernels).

    Attributes
    ----------
    n_segments: N, segments per section; n_chain = 6 N + 1 chain joints.
    master_qpos_adr, master_dof_adr (2,): shoulder, elbow.  master_actuator_ids (2,).
    chain_qpos_adr, chain_dof_adr (n_chain,): chain joints in MuJoCo order (per segment slide, hinge;
        tip slide last).  chain_actuator_ids (n_chain,): the servo/motor of each chain joint (empty for
        muscle actuation).
    muscle_actuator_ids (6,): the muscle groups [s1 +r, s1 -r, s2 +r, ...] (``muscle_commands`` order;
        empty unless muscle actuation); muscle_radius, muscle_max_force (3,): r (m), F_max (N).
    master_site_id, tip_site_id: ``master_tip_site``, ``octarm_tip_site``.
    master_base_pos, octarm_base_pos (3,): world positions of the bases (task space origin).
    C (n_chain, 6), R (6, n_chain), L0 (3,): joints = C [d - L0, k d];  [d - L0, k d] = R joints.
    section, is_hinge, segment (n_chain,) int64.
    joint_stiffness (n_chain,): MuJoCo chain-joint stiffness; shape_stiffness (n_chain,): E_shape weights
        (= the slide stiffness, 0 on hinges).
    seg_kb (3,) = N Kb; ke (3,) = Ke.
    armature (n_chain,); servo_kp, servo_kv (n_chain,) (zeros for torque actuation); tip_mass (kg).
    """

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
    armature: np.ndarray
    servo_kp: np.ndarray
    servo_kv: np.ndarray
    tip_mass: float

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.type == "np.ndarray":
                integer = f.name.endswith(("_adr", "_ids")) or f.name in ("section", "is_hinge", "segment")
                dtype = np.int64 if integer else np.float64
                object.__setattr__(self, f.name, _ro(getattr(self, f.name), dtype))

    @property
    def n_chain(self) -> int:
        return int(self.C.shape[0])

    @property
    def elastic_args(self) -> tuple:
        """Constant arguments of ``chain_elastic_correction`` after ``qpos_chain`` (and before ``out``)."""
        return (self.R, self.C, self.L0, self.section, self.is_hinge, self.seg_kb, self.ke,
                self.joint_stiffness, self.shape_stiffness)

    # --- allocating convenience wrappers ----------------------------------------------------------
    def joints_from_q2(self, q2) -> np.ndarray:
        """(n_chain,) chain joint positions on the CC manifold for q2 (6,)."""
        out = np.empty(self.n_chain)
        chain_joints_from_q2(np.asarray(q2, dtype=float), self.C, self.L0, out)
        return out

    def jacobian(self, q2) -> np.ndarray:
        """A(q2) = d joints / d q2, (n_chain, 6)."""
        out = np.empty((self.n_chain, 6))
        chain_joints_jacobian(np.asarray(q2, dtype=float), self.C, out)
        return out

    def q2_from_joints(self, qpos_chain) -> np.ndarray:
        """Sensed q2 (6,) from chain joint positions (n_chain,)."""
        out = np.empty(6)
        chain_q2_from_joints(np.asarray(qpos_chain, dtype=float), self.R, self.L0, out)
        return out

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
        """Muscle group commands (6,) for T2 at q2 and the number of saturated groups
        (``muscle_commands``)."""
        out = np.empty(6)
        n_sat = muscle_commands(np.asarray(q2, dtype=float), np.asarray(T2, dtype=float),
                                self.muscle_radius, self.muscle_max_force, out)
        return out, int(n_sat)

    def elastic_correction(self, qpos_chain) -> np.ndarray:
        """Force (n_chain,) to add to MuJoCo's springs (see ``chain_elastic_correction``)."""
        out = np.empty(self.n_chain)
        chain_elastic_correction(np.asarray(qpos_chain, dtype=float), *self.elastic_args, out)
        return out

    def elastic_energy(self, qpos_chain) -> float:
        """Exact discrete elastic energy E (J) of ``chain_elastic_correction``."""
        return float(chain_elastic_energy(np.asarray(qpos_chain, dtype=float), self.R, self.C, self.L0,
                                          self.section, self.is_hinge, self.seg_kb, self.ke,
                                          self.shape_stiffness))

    # --- MjData helpers ---------------------------------------------------------------------------
    def chain_qpos(self, d: mujoco.MjData) -> np.ndarray:
        return d.qpos[self.chain_qpos_adr].copy()

    def chain_qvel(self, d: mujoco.MjData) -> np.ndarray:
        return d.qvel[self.chain_dof_adr].copy()

    def set_q2(self, d: mujoco.MjData, q2, dq2=None) -> None:
        """Put the chain on the CC manifold at q2 (and velocity A dq2; zero if None)."""
        d.qpos[self.chain_qpos_adr] = self.joints_from_q2(q2)
        d.qvel[self.chain_dof_adr] = 0.0 if dq2 is None else self.jacobian(q2) @ np.asarray(dq2, float)

    def sense(self, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(q2, dq2) sensed from the chain joints of d."""
        return self.sense_joints(self.chain_qpos(d), self.chain_qvel(d))

    def master_tip(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """[X, Z] of master_tip_site relative to master_base (needs up-to-date kinematics)."""
        p = d.site_xpos[self.master_site_id] - self.master_base_pos
        return np.array([p[0], p[2]])

    def octarm_tip(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """[X, Z] of octarm_tip_site relative to octarm_base (needs up-to-date kinematics)."""
        p = d.site_xpos[self.tip_site_id] - self.octarm_base_pos
        return np.array([p[0], p[2]])


# kernels compiled by harness.loop.fast (numba) together with controllers/
KERNELS = ("chain_joints_from_q2", "chain_joints_jacobian", "chain_joints_rate_add", "chain_q2_from_joints",
           "chain_sense", "chain_force_from_T2", "muscle_commands", "chain_extension",
           "chain_elastic_correction", "chain_elastic_energy")
