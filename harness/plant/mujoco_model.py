"""MuJoCo "true plant": master + discretized Octarm built from the MJCF in ``mjcf/`` by editing an MjSpec.

Frames and units
----------------
SI units (m, kg, s, rad).  Both robots move in planes parallel to the world x-z plane; hinges turn about
+y (a positive angle takes +z toward +x).  Each robot's task space [X, Z] is relative to its own base:
``master_base`` at world (0, -0.3, 0) and ``octarm_base`` at world (0, +0.3, 0).

Octarm discretization ("hinges at segment midpoints", second order)
--------------------------------------------------------------------
Section i (0..2) with current arc length d_i, curvature k_i, bend Theta_i = k_i d_i and rest length L0_i is
split into N segments of current length l_i = d_i / N (rest l0_i = L0_i / N).  Body
``octarm_s{i}_seg{j}_body`` sits at the MIDPOINT of segment j; its joints are, in order,

* slide ``octarm_s{i}_seg{j}_slide`` along the parent's tangent (the body z before the hinge): the
  extension of the rod from the previous node (midpoint, or the base) to this one;
* hinge ``octarm_s{i}_seg{j}_hinge`` about +y: the bend Theta_i / N of one segment.

Body positions relative to the parent are the rest rod lengths: l0_0 / 2 for the very first body,
(l0_{i-1} + l0_i) / 2 for j = 0 and i >= 1, l0_i otherwise.  After the last segment, ``octarm_tip_body``
at l0_2 / 2 with one slide ``octarm_tip_slide`` carries ``octarm_tip_site``.

On the constant-curvature (CC) manifold, with e_i = d_i - L0_i, the chain joints are
  hinge(i, j) = Theta_i / N,     slide(i, j >= 1) = e_i / N,
  slide(i, 0) = (e_{i-1} + e_i) / (2N)  (drop e_{-1}),     tip slide = e_2 / (2N),
i.e. joints = C u with u = [e_0, e_1, e_2, Theta_0, Theta_1, Theta_2] and a constant C (n_chain, 6).
The rod from node j-1 to node j points along the tangent at the arc point halfway between the two
midpoints (midpoint rule on the tangent; one-sided half rods at the base, section boundaries and tip):
node positions approximate the arc midpoints to O(1/N^2) and the final orientation is exact.

Chain joint order (``ChainMap.chain_*`` arrays, "qpos_chain"): the MuJoCo order, i.e. for each section,
for each segment, slide then hinge; the tip slide last.  n_chain = 6 N + 1.

Mass: segment (i, j) is a point-like mass m_i / N at its body origin (the segment midpoint) with rod
inertia about y (m_i / N) l0_i^2 / 12 plus the slice inertia (see ``_segment_inertias``: trapezoidal
split over the two rod orientations bounding the segment, which keeps the slice term second order;
putting all of it on the segment's own body would be first order, because the body frame carries the
tangent at the segment END).  The tip body needs a mass for MuJoCo: ``TIP_MASS_FRACTION * m_2 / N``,
taken from the last segment so that the total mass is exact (a modelled mismatch of O(1e-3 / N^2)).

Elasticity: MuJoCo joint springs (hinge N Kb_i / L0_i; slide N Ke_i inside a section, series
combinations for the half/boundary rods) plus ``chain_elastic_correction`` (applied by the harness
through qfrc_applied at every physics step) give -grad of the exact discrete energy, equal to the
analytic elastic force on the CC manifold.  Without the correction the springs alone are exact only
at rest length with equal neighbouring extensions.  Viscous damping of SlaveParams (on q2 rates) is
MuJoCo joint damping (``_joint_damping``, integrated implicitly; exact at rest length on the manifold).

Actuation: ``servo`` = a position actuator per chain joint (force kp (ctrl - q) - kv qdot, ctrl = the
joint target, e.g. ``joints_from_q2``), kp = M_jj (2 pi f)^2, kv = 2 zeta (2 pi f) M_jj with M_jj the
diagonal of the joint-space inertia (armature included) at the straight rest configuration; add
kv qdot_ref through qfrc_applied for velocity tracking.  ``torque`` = a motor per chain joint (gear 1).
Master: two motors.  Armature: ``armature_fraction`` times the section inertia scale on every chain
joint, plus one segment mass on the tip slide (see ``_joint_armature``), a modelled mismatch of
relative size ~ fraction / (6 N) in M2.

``enforce_cc``: joint equalities (hinges of a section equal; interior slides equal; first slide = half
the next; tip slide = half the last interior slide) and fixed-tendon equalities (boundary slide = mean
of its neighbours; for N = 1 one tendon s00 - s10 + s20 - tip = 0), solref/solimp ``CC_SOLREF``/
``CC_SOLIMP``: 3N - 3 hinge and 3N - 2 slide constraints leave exactly the 6 CC coordinates.

Stability (measured, default SlaveParams, 1 ms, implicitfast, loaded, correction every step): the
joint springs are integrated explicitly and the discrete chain gets stiffer with N (h w_max = 0.82,
1.19, 1.69, 2.39 at N = 8, 16, 32, 64; ``stiffness_courant_number``).  N <= 32 steps stably; N = 48
diverges in torque mode (use a smaller physics_dt, enforce_cc, or the ``discrete`` integrator, which
treats joint stiffness implicitly and was stable up to N = 64 at 1 ms).

The per-step functions ``chain_*`` below are plain loops over float64/int64 arrays (no Python objects,
no np.dot/np.linalg) so they can be compiled with numba from the harness' step kernel; each writes into
an ``out`` array.  ``ChainMap`` has allocating wrappers for interactive use.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from controllers.params import MasterParams, SlaveParams
from harness.config import ACTUATIONS, PlantConfig

MJCF_DIR = Path(__file__).resolve().parent.parent / "mjcf"
SCENE_XML = MJCF_DIR / "scene.xml"

N_SECTIONS = 3
MAX_SEGMENTS = 64
# Tip body mass as a fraction of one last-section segment mass (taken from that segment).
TIP_MASS_FRACTION = 1e-3
# Extra armature of the tip slide, in last-section segment masses m_2 / N (see _joint_armature).
TIP_SLIDE_ARMATURE = 1.0
# Equality constraints holding the sections at constant curvature (api-notes: tight values).
CC_SOLREF = (0.002, 1.0)
CC_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)

_INTEGRATORS = {
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    "discrete": mujoco.mjtIntegrator.mjINT_DISCRETE,  # not in harness.config.INTEGRATORS (yet)
}


class PlantModelError(ValueError):
    """The plant model cannot be built: bad MJCF file (named, with MuJoCo's message) or bad option."""


# ================================================================================================
# Numba-compatible per-step kernels (plain loops, float64/int64 arrays in, results written to `out`)
# ================================================================================================

def chain_joints_from_q2(q2, C, L0, out):
    """CC manifold -> chain joints.  q2 (6,) = [d (m), k (1/m)]; C (n_chain, 6); L0 (3,); out (n_chain,).

    out = C u with u = [d - L0, k * d] (extensions in m, section bends in rad).
    """
    n = C.shape[0]
    u = np.empty(6)
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
    w = np.empty(6)
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
    e = np.zeros(3)
    sq = np.zeros(3)
    for c in range(n):
        q = qpos_chain[c]
        for i in range(3):
            e[i] += R[i, c] * q
        if is_hinge[c] == 1:
            sq[section[c]] += q * q
    dEdd = np.empty(3)
    dinv = np.empty(3)
    for i in range(3):
        d = L0[i] + e[i]
        dinv[i] = 1.0 / d
        dEdd[i] = -0.5 * seg_kb[i] * sq[i] * dinv[i] * dinv[i] + ke[i] * e[i]
    # shape term: g = k_shape * r on slides;  grad = g - P^T (C_e^T g)
    ctg = np.zeros(3)
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
    e = np.zeros(3)
    sq = np.zeros(3)
    for c in range(n):
        q = qpos_chain[c]
        for i in range(3):
            e[i] += R[i, c] * q
        if is_hinge[c] == 1:
            sq[section[c]] += q * q
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


def _segment_inertias(slave: SlaveParams, N: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Per-body masses (3, N) [kg], inertias about y (3, N) [kg m^2] and the tip mass [kg].

    Rod term (m_i / N) l0_i^2 / 12 on the segment's own body.  Slice inertia I_s,i / N of segment (i, j)
    (slice_inertia is per unit *normalized* material coordinate, i.e. the section total) is split in
    halves between the two bodies whose frames carry the tangents at the segment's ends: the parent
    (start tangent) and the segment's own body (end tangent) -- the trapezoidal rule on the tangent rate,
    second order.  The first segment's start half goes to the (fixed) base and is dropped: it has no
    kinetic energy.
    """
    m = np.asarray(slave.masses)
    L0 = np.asarray(slave.rest_lengths)
    Is = np.asarray(slave.slice_inertia)
    mass = np.repeat((m / N)[:, None], N, axis=1)
    iyy = mass * (L0[:, None] / N) ** 2 / 12.0
    for i in range(3):
        for j in range(N):
            iyy[i, j] += 0.5 * Is[i] / N  # end half of own segment
            # start half of the next segment (same orientation as this body)
            if j + 1 < N:
                iyy[i, j] += 0.5 * Is[i] / N
            elif i + 1 < 3:
                iyy[i, j] += 0.5 * Is[i + 1] / N
    tip_mass = TIP_MASS_FRACTION * m[2] / N
    mass[2, N - 1] -= tip_mass
    return mass, iyy, tip_mass


def _slide_pattern(per_section, N: int, layout: dict) -> np.ndarray:
    """Per-chain-joint values of a rod property that adds like a spring (stiffness, damping) for the
    slides, from its per-section value v_i: N v_i inside a section (a rod of rest length L0_i / N),
    2N v for the first half rod and the tip half rod, and the two half rods of sections i-1 and i in
    series at a boundary, 2N v_{i-1} v_i / (v_{i-1} + v_i).  Hinge entries are 0."""
    v = np.asarray(per_section, dtype=float)
    n = layout["C"].shape[0]
    out = np.zeros(n)
    for c in range(n):
        if layout["is_hinge"][c]:
            continue
        i, j = int(layout["section"][c]), int(layout["segment"][c])
        if j == N:  # tip
            out[c] = 2.0 * N * v[2]
        elif j >= 1:
            out[c] = N * v[i]
        elif i == 0:
            out[c] = 2.0 * N * v[0]
        else:
            a, b = v[i - 1], v[i]
            out[c] = 2.0 * N * a * b / (a + b) if a + b > 0 else 0.0
    return out


def _hinge_values(per_section, layout: dict) -> np.ndarray:
    """Per-chain-joint values for the hinges from a per-section value (0 on slides)."""
    v = np.asarray(per_section, dtype=float)
    return np.where(layout["is_hinge"] == 1, v[layout["section"]], 0.0)


def _joint_stiffness(slave: SlaveParams, N: int, layout: dict) -> np.ndarray:
    """MuJoCo joint stiffness per chain joint (N m/rad for hinges, N/m for slides).

    Hinge: N Kb_i / L0_i (a segment of rest length L0_i / N with bending stiffness Kb_i), reproducing
    1/2 Kb_i Theta_i^2 / L0_i per section at rest length.  Slides: `_slide_pattern` of Ke (N Ke_i
    inside a section, half rods 2N Ke, boundary rods in series).  For uniform section extensions this
    already gives sum_i 1/2 Ke_i (d_i - L0_i)^2; the elastic correction handles the length dependence
    and unequal neighbours exactly.
    """
    L0 = np.asarray(slave.rest_lengths)
    return (_hinge_values(N * np.asarray(slave.bending_stiffness) / L0, layout)
            + _slide_pattern(slave.extension_stiffness, N, layout))


def _joint_damping(slave: SlaveParams, N: int, layout: dict) -> np.ndarray:
    """MuJoCo joint damping per chain joint (N m s/rad, N s/m), integrated implicitly by MuJoCo.

    The analytic model's viscous damping on q2 rates, dissipating De_i dd_i^2 + Dk_i dk_i^2, mapped
    like the springs: slides get `_slide_pattern` of De; hinges get N Dk_i / L0_i^2 (at k = 0 and
    d = L0 a hinge rate is dk d / N, so N hinges dissipate Dk dk^2).  Exact at rest length on the CC
    manifold; the length dependence is a modelled mismatch.  (Applying -D dq2 as an explicit force
    instead is unstable on the light distal joints at 1 ms.)
    """
    L0 = np.asarray(slave.rest_lengths)
    return (_hinge_values(N * np.asarray(slave.bending_damping) / L0**2, layout)
            + _slide_pattern(slave.extension_damping, N, layout))


def _joint_armature(slave: SlaveParams, N: int, layout: dict, fraction: float) -> np.ndarray:
    """Joint armature per chain joint: ``fraction`` times the section's own inertia scale.

    Hinges of section i: fraction * m_i L0_i^2 / 3 (kg m^2, the section as a rod about its base);
    slides: fraction * m_i (kg).  The tip slide moves only the tip site and the tiny tip mass, yet
    carries a half-rod spring 2 N Ke_2: alone it would be the fastest mode of the model (h w = 2.5 at
    N = 32, 1 ms).  It gets TIP_SLIDE_ARMATURE * m_2 / N more (one segment mass), which brings it below
    the bulk chain modes; since the tip slide is (d_2 - L0_2) / (2N), this adds only m_2 / (4 N^3) to
    M2[d_2, d_2] (third order).  The same value on every joint of a section,
    independent of N (it is a regularizer of the joint-space inertia: it lifts the tiny diagonal entries
    of the distal segments and helps the equality constraints).  Its contribution to the q2 inertia,
    A^T diag(armature) A, is a modelled mismatch that decays like 1/N: measured ~ fraction / (6 N) of M2
    for the default parameters (reported separately by ``harness.fidelity``).  It is needed: with
    fraction = 0 the loaded N = 8 and N = 16 plants diverge within 1 s at 1 ms (measured; they are
    stable with the default 0.01, or with enforce_cc).
    """
    m = np.asarray(slave.masses)
    L0 = np.asarray(slave.rest_lengths)
    n = layout["C"].shape[0]
    a = np.zeros(n)
    for c in range(n):
        i = int(layout["section"][c])
        a[c] = fraction * (m[i] * L0[i] ** 2 / 3.0 if layout["is_hinge"][c] else m[i])
    a[-1] += TIP_SLIDE_ARMATURE * m[2] / N
    return a


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
        tip slide last).  chain_actuator_ids (n_chain,): the servo/motor of each chain joint.
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

    def dq2_from_joints(self, qpos_chain, qvel_chain) -> np.ndarray:
        """Sensed dq2/dt (6,) from chain joint positions and velocities (n_chain,)."""
        return self.sense_joints(qpos_chain, qvel_chain)[1]

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


# ================================================================================================
# Spec construction
# ================================================================================================

def _check_segments(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not (1 <= int(n) <= MAX_SEGMENTS):
        raise PlantModelError(f"plant.segments = {n!r}: must be an integer in [1, {MAX_SEGMENTS}]")
    return int(n)


def _load_spec(path: Path) -> mujoco.MjSpec:
    path = Path(path)
    if not path.is_file():
        raise PlantModelError(f"MJCF file not found: {path}")
    try:
        return mujoco.MjSpec.from_file(os.fspath(path))
    except ValueError as exc:  # MuJoCo's parse/resolve errors
        raise PlantModelError(f"cannot load MJCF {path}: {exc}") from None


def _compile(spec: mujoco.MjSpec, what: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        raise PlantModelError(f"cannot compile {what}: {exc}") from None


def _set_master(spec: mujoco.MjSpec, master: MasterParams, src: Path) -> None:
    """Overwrite lengths, inertials and joint damping of the master from MasterParams."""
    names = (("master_upper_link", "master_upper_link_geom", "master_shoulder_joint"),
             ("master_fore_link", "master_fore_link_geom", "master_elbow_joint"))
    for k, (body_name, geom_name, joint_name) in enumerate(names):
        body, geom, joint = spec.body(body_name), spec.geom(geom_name), spec.joint(joint_name)
        if body is None or geom is None or joint is None:
            raise PlantModelError(f"{src}: master element missing ({body_name}/{geom_name}/{joint_name})")
        l, mass = master.lengths[k], master.masses[k]
        i_rod = mass * l * l / 12.0
        body.mass = mass
        body.ipos = [0.0, 0.0, 0.5 * l]
        body.iquat = [1.0, 0.0, 0.0, 0.0]
        # about x = about y (slender rod); about z a thin-rod value, capped for the triangle inequality
        body.inertia = [i_rod, i_rod, min(1e-4 * mass, i_rod)]
        body.explicitinertial = True
        geom.fromto = [0.0, 0.0, 0.0, 0.0, 0.0, l]
        joint.damping[0] = master.damping[k]
        if k == 1:
            body.pos = [0.0, 0.0, master.lengths[0]]
    site = spec.site("master_tip_site")
    if site is None:
        raise PlantModelError(f"{src}: master_tip_site missing")
    site.pos = [0.0, 0.0, master.lengths[1]]


def _gravity(master: MasterParams, slave: SlaveParams) -> list[float]:
    gx, gz = slave.gravity
    if not np.allclose([gx, gz], [0.0, -master.gravity], rtol=1e-12, atol=1e-12):
        raise PlantModelError(
            f"master.gravity = {master.gravity} (along -Z) and slave.gravity = {slave.gravity} differ: "
            "both robots share one MuJoCo world")
    return [gx, 0.0, gz]


def _add_octarm(spec: mujoco.MjSpec, slave: SlaveParams, plant: PlantConfig, N: int, layout: dict, src: Path):
    base = spec.body("octarm_base")
    if base is None:
        raise PlantModelError(f"{src}: body octarm_base missing")
    d_hinge, d_slide = spec.find_default("octarm_hinge"), spec.find_default("octarm_slide")
    d_geom = spec.find_default("octarm_segment_visual")
    if d_hinge is None or d_slide is None or d_geom is None:
        raise PlantModelError(f"{src}: default classes octarm_hinge/octarm_slide/"
                              "octarm_segment_visual missing")
    L0 = np.asarray(slave.rest_lengths)
    l0 = L0 / N
    mass, iyy, tip_mass = _segment_inertias(slave, N)
    stiff = _joint_stiffness(slave, N, layout)
    arm = _joint_armature(slave, N, layout, plant.armature_fraction)
    damp = _joint_damping(slave, N, layout)
    joint_names = []
    parent = base
    c = 0
    for i in range(3):
        for j in range(N):
            if j >= 1:
                z = l0[i]
            elif i >= 1:
                z = 0.5 * (l0[i - 1] + l0[i])
            else:
                z = 0.5 * l0[0]
            name = f"octarm_s{i}_seg{j}"
            body = parent.add_body(name=f"{name}_body", pos=[0.0, 0.0, z])
            body.mass = float(mass[i, j])
            body.ipos = [0.0, 0.0, 0.0]
            # rod: about x = about y; about the rod axis a tiny but valid value
            body.inertia = [float(iyy[i, j]), float(iyy[i, j]), float(1e-3 * iyy[i, j])]
            body.explicitinertial = True
            for kind, dflt in (("slide", d_slide), ("hinge", d_hinge)):
                jn = body.add_joint(dflt, name=f"{name}_{kind}")
                jn.stiffness[0] = float(stiff[c])
                jn.damping[0] = float(damp[c])
                jn.armature = float(arm[c])
                joint_names.append(jn.name)
                c += 1
            body.add_geom(d_geom, name=f"{name}_geom",
                          fromto=[0.0, 0.0, -0.5 * l0[i], 0.0, 0.0, 0.5 * l0[i]])
            parent = body
    tip = parent.add_body(name="octarm_tip_body", pos=[0.0, 0.0, 0.5 * l0[2]])
    tip.mass = float(tip_mass)
    tip.ipos = [0.0, 0.0, 0.0]
    it = float(tip_mass * (0.1 * l0[2]) ** 2)
    tip.inertia = [it, it, it]
    tip.explicitinertial = True
    jn = tip.add_joint(d_slide, name="octarm_tip_slide")
    jn.stiffness[0] = float(stiff[c])
    jn.damping[0] = float(damp[c])
    jn.armature = float(arm[c])
    joint_names.append(jn.name)
    tip.add_site(name="octarm_tip_site")
    return joint_names, stiff, arm, tip_mass


def _add_actuators(spec: mujoco.MjSpec, joint_names: list[str], actuation: str) -> list[str]:
    names = []
    for jn in joint_names:
        if actuation == "servo":
            a = spec.add_actuator(name=f"{jn}_servo", target=jn, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.set_to_position(kp=1.0, kv=0.0)  # gains set from the inertia in build_spec
        else:
            a = spec.add_actuator(name=f"{jn}_motor", target=jn, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.set_to_motor()
        names.append(a.name)
    return names


def _add_cc_equalities(spec: mujoco.MjSpec, N: int) -> None:
    """Equality constraints keeping each section at constant curvature (see module docstring)."""

    def joint_eq(name, j1, j2, a1):
        eq = spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_JOINT, name1=j1, name2=j2,
                               objtype=mujoco.mjtObj.mjOBJ_JOINT)
        eq.data[:5] = [0.0, a1, 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = list(CC_SOLREF), list(CC_SOLIMP)

    def tendon_eq(name, coefs):
        t = spec.add_tendon(name=f"{name}_tendon")
        for jn, cf in coefs:
            t.wrap_joint(jn, cf)
        eq = spec.add_equality(name=f"{name}_equality", type=mujoco.mjtEq.mjEQ_TENDON,
                               name1=t.name, objtype=mujoco.mjtObj.mjOBJ_TENDON)
        eq.data[:5] = [0.0, 0.0, 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = list(CC_SOLREF), list(CC_SOLIMP)

    def sl(i, j):
        return f"octarm_s{i}_seg{j}_slide"

    for i in range(3):
        for j in range(1, N):
            joint_eq(f"octarm_s{i}_seg{j}_hinge_equality", f"octarm_s{i}_seg{j}_hinge",
                     f"octarm_s{i}_seg0_hinge", 1.0)
    if N == 1:
        # 4 slides, 3 extensions: s00 - s10 + s20 - tip = 0 on the manifold
        tendon_eq("octarm_slide_cc", [(sl(0, 0), 1.0), (sl(1, 0), -1.0), (sl(2, 0), 1.0),
                                      ("octarm_tip_slide", -1.0)])
        return
    for i in range(3):
        for j in range(2, N):
            joint_eq(f"octarm_s{i}_seg{j}_slide_equality", sl(i, j), sl(i, 1), 1.0)
    joint_eq("octarm_s0_seg0_slide_equality", sl(0, 0), sl(0, 1), 0.5)
    for i in (1, 2):
        tendon_eq(f"octarm_s{i}_boundary", [(sl(i, 0), 1.0), (sl(i - 1, 1), -0.5), (sl(i, 1), -0.5)])
    joint_eq("octarm_tip_slide_equality", "octarm_tip_slide", sl(2, 1), 0.5)


def _validate_plant(plant: PlantConfig) -> int:
    N = _check_segments(plant.segments)
    if plant.actuation not in ACTUATIONS:
        raise PlantModelError(f"plant.actuation = {plant.actuation!r}: must be one of {ACTUATIONS}")
    if plant.integrator not in _INTEGRATORS:
        raise PlantModelError(
            f"plant.integrator = {plant.integrator!r}: must be one of {tuple(_INTEGRATORS)}")
    for f in ("physics_dt", "servo_frequency", "servo_damping_ratio"):
        v = getattr(plant, f)
        if not (np.isfinite(v) and v > 0):
            raise PlantModelError(f"plant.{f} = {v!r}: must be finite and > 0")
    if not (np.isfinite(plant.armature_fraction) and plant.armature_fraction >= 0):
        raise PlantModelError(f"plant.armature_fraction = {plant.armature_fraction!r}: must be >= 0")
    return N


def _build(master: MasterParams, slave: SlaveParams, plant: PlantConfig, scene=None):
    N = _validate_plant(plant)
    if scene is None:
        scene = getattr(plant, "scene_xml", None)
    scene = SCENE_XML if scene is None else Path(scene)
    spec = _load_spec(scene)
    spec.modelname = f"teleop_scene_n{N}"
    spec.option.timestep = float(plant.physics_dt)
    spec.option.integrator = _INTEGRATORS[plant.integrator]
    spec.option.gravity = _gravity(master, slave)
    _set_master(spec, master, scene)
    layout = chain_layout(N)
    joint_names, stiff, arm, tip_mass = _add_octarm(spec, slave, plant, N, layout, scene)
    act_names = _add_actuators(spec, joint_names, plant.actuation)
    if plant.enforce_cc:
        _add_cc_equalities(spec, N)
    kp = np.zeros(len(joint_names))
    kv = np.zeros(len(joint_names))
    if plant.actuation == "servo":
        m = _compile(spec, "the plant model")
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)  # qpos0 = straight, rest length
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        dof = np.array([m.jnt_dofadr[m.joint(n).id] for n in joint_names])
        w = 2.0 * np.pi * plant.servo_frequency
        Mjj = np.diag(M)[dof]
        kp = Mjj * w * w
        kv = 2.0 * plant.servo_damping_ratio * w * Mjj
        for a_name, p, v in zip(act_names, kp, kv, strict=True):
            spec.actuator(a_name).set_to_position(kp=float(p), kv=float(v))
    return spec, N, layout, joint_names, act_names, stiff, arm, tip_mass, kp, kv


def build_spec(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
               scene_xml: str | os.PathLike | None = None) -> mujoco.MjSpec:
    """The plant as an editable ``mujoco.MjSpec`` (scene.xml + master from ``master`` + generated Octarm).

    master/slave: the *plant's* parameters (may differ from the controller's nominal ones).
    plant: segments N (int in [1, 64]), actuation, enforce_cc, physics_dt, integrator, servo tuning,
    armature_fraction.  scene_xml: alternative scene file (default ``mjcf/scene.xml``); it must define
    the named master elements, ``octarm_base`` and the ``octarm_*`` default classes.
    Raises PlantModelError on bad input or MJCF.
    """
    return _build(master, slave, plant, scene_xml)[0]


def build_model(master: MasterParams, slave: SlaveParams, plant: PlantConfig, *,
                scene_xml: str | os.PathLike | None = None) -> tuple[mujoco.MjModel, ChainMap]:
    """Compiled plant model and its ``ChainMap`` (addresses + constant maps); see ``build_spec``."""
    spec, N, layout, joint_names, act_names, stiff, arm, tip_mass, kp, kv = _build(master, slave, plant,
                                                                                   scene_xml)
    m = _compile(spec, "the plant model")
    Ke = np.asarray(slave.extension_stiffness)
    shape_w = np.where(layout["is_hinge"] == 0, stiff, 0.0)

    def jid(name):
        return m.joint(name).id

    master_j = [jid("master_shoulder_joint"), jid("master_elbow_joint")]
    chain_j = [jid(n) for n in joint_names]
    cmap = ChainMap(
        n_segments=N,
        actuation=plant.actuation,
        enforce_cc=bool(plant.enforce_cc),
        master_qpos_adr=_ro(m.jnt_qposadr[master_j], np.int64),
        master_dof_adr=_ro(m.jnt_dofadr[master_j], np.int64),
        master_actuator_ids=_ro([m.actuator(n).id for n in ("master_shoulder_motor", "master_elbow_motor")],
                                np.int64),
        chain_qpos_adr=_ro(m.jnt_qposadr[chain_j], np.int64),
        chain_dof_adr=_ro(m.jnt_dofadr[chain_j], np.int64),
        chain_actuator_ids=_ro([m.actuator(n).id for n in act_names], np.int64),
        master_site_id=int(m.site("master_tip_site").id),
        tip_site_id=int(m.site("octarm_tip_site").id),
        master_base_pos=_ro(m.body("master_base").pos),
        octarm_base_pos=_ro(m.body("octarm_base").pos),
        C=_ro(layout["C"]),
        R=_ro(layout["R"]),
        L0=_ro(slave.rest_lengths),
        section=_ro(layout["section"], np.int64),
        is_hinge=_ro(layout["is_hinge"], np.int64),
        segment=_ro(layout["segment"], np.int64),
        joint_stiffness=_ro(stiff),
        shape_stiffness=_ro(shape_w),
        seg_kb=_ro(N * np.asarray(slave.bending_stiffness)),
        ke=_ro(Ke),
        armature=_ro(arm),
        servo_kp=_ro(kp),
        servo_kv=_ro(kv),
        tip_mass=float(tip_mass),
    )
    return m, cmap


def stiffness_courant_number(m: mujoco.MjModel, cm: ChainMap) -> float:
    """h * w_max of the chain's joint springs (and servo kp) against its inertia at qpos0 (dimensionless).

    w_max^2 is the largest generalized eigenvalue of K = diag(joint stiffness + kp) and the chain block of
    M (armature included).  Semi-implicit integration of undamped springs needs h w_max < 2; servo
    damping (implicit under implicitfast) and equality constraints relax this in practice.
    """
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    idx = np.asarray(cm.chain_dof_adr)
    Mc = M[np.ix_(idx, idx)]
    k = np.asarray(cm.joint_stiffness) + np.asarray(cm.servo_kp)
    # eigenvalues of L^-1 K L^-T with M = L L^T
    L = np.linalg.cholesky(Mc)
    Li = np.linalg.inv(L)
    w2 = np.linalg.eigvalsh(Li @ (k[:, None] * Li.T))
    return float(m.opt.timestep * np.sqrt(max(w2[-1], 0.0)))


def export_mjcf(master: MasterParams, slave: SlaveParams, plant: PlantConfig, path) -> Path:
    """Write the generated plant MJCF (``spec.to_xml()``) to ``path`` and check it re-loads.

    The file is self-contained (includes resolved) and opens in MuJoCo's viewer for any N.  MuJoCo
    writes numbers with about 6 significant digits, so simulate with ``build_model`` (full precision);
    the export is for viewing and sharing.
    """
    spec = build_spec(master, slave, plant)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(spec.to_xml())
    try:
        mujoco.MjModel.from_xml_path(os.fspath(path))
    except ValueError as exc:
        raise PlantModelError(f"exported MJCF {path} does not re-load: {exc}") from None
    return path


__all__ = [
    "CC_SOLIMP", "CC_SOLREF", "MJCF_DIR", "SCENE_XML", "TIP_MASS_FRACTION", "ChainMap", "PlantModelError",
    "build_model", "build_spec", "chain_sense", "chain_elastic_correction", "chain_elastic_energy",
    "chain_force_from_T2", "chain_joints_from_q2", "chain_joints_jacobian", "chain_joints_rate_add",
    "chain_layout",
    "chain_q2_from_joints", "export_mjcf", "stiffness_courant_number",
]

# kernels compiled by harness.fast (numba) together with controllers/
KERNELS = ("chain_joints_from_q2", "chain_joints_jacobian", "chain_joints_rate_add", "chain_q2_from_joints",
           "chain_sense",
           "chain_force_from_T2", "chain_elastic_correction", "chain_elastic_energy")
