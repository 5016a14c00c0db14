"""Per-joint physical parameters of the discretized Octarm chain, from the slave parameters: segment
masses and inertias, joint stiffness, damping and armature (layout and maps: `harness.plant.chain_map`;
the model they go into: `harness.plant.mujoco_model`, whose docstring gives the derivations).
"""

from __future__ import annotations

import numpy as np

from controllers.params import SlaveParams

TIP_MASS_FRACTION = 1e-3  # tip body mass as a fraction of one last-section segment mass (taken from it)
TIP_SLIDE_ARMATURE = 1.0  # extra armature of the tip slide, in last-section segment masses m_2 / N


def segment_inertias(slave: SlaveParams, N: int) -> tuple[np.ndarray, np.ndarray, float]:
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


def slide_pattern(per_section, N: int, layout: dict) -> np.ndarray:
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


def hinge_values(per_section, layout: dict) -> np.ndarray:
    """Per-chain-joint values for the hinges from a per-section value (0 on slides)."""
    v = np.asarray(per_section, dtype=float)
    return np.where(layout["is_hinge"] == 1, v[layout["section"]], 0.0)


def joint_stiffness(slave: SlaveParams, N: int, layout: dict) -> np.ndarray:
    """MuJoCo joint stiffness per chain joint (N m/rad for hinges, N/m for slides).

    Hinge: N Kb_i / L0_i (a segment of rest length L0_i / N with bending stiffness Kb_i), reproducing
    1/2 Kb_i Theta_i^2 / L0_i per section at rest length.  Slides: `_slide_pattern` of Ke (N Ke_i
    inside a section, half rods 2N Ke, boundary rods in series).  For uniform section extensions this
    already gives sum_i 1/2 Ke_i (d_i - L0_i)^2; the elastic correction handles the length dependence
    and unequal neighbours exactly.
    """
    L0 = np.asarray(slave.rest_lengths)
    return (hinge_values(N * np.asarray(slave.bending_stiffness) / L0, layout)
            + slide_pattern(slave.extension_stiffness, N, layout))


def joint_damping(slave: SlaveParams, N: int, layout: dict, bending_viscosity=(0.0, 0.0, 0.0),
                  extension_viscosity=(0.0, 0.0, 0.0)) -> np.ndarray:
    """MuJoCo joint damping per chain joint (N m s/rad, N s/m), integrated implicitly by MuJoCo.

    Two viscous terms, added:

    * The analytic model's viscous damping on q2 rates (SlaveParams ``bending_damping`` Dk, N m^2 s on
      k-rates, ``extension_damping`` De, N s/m on d-rates), dissipating De_i dd_i^2 + Dk_i dk_i^2.
    * The rod's MATERIAL (Kelvin-Voigt) damping, the same as the Cosserat plant's
      (``harness.plant.cosserat``): bending viscosity eta_b (N m^2 s, moment eta_b dkappa/dt) and
      extension viscosity eta_a (N s, axial force eta_a d(strain)/dt), per section.  A rigid segment
      chain of segment length h = L0_i / N discretizing that rod gets, like its springs (hinge EI / h,
      slide EA / h = Ke L0 / h):  hinge damping eta_b / h,  slide damping eta_a / h
      (``cosserat.hinge_damping`` / ``slide_damping``), with the springs' half-rod and series rules for
      the slides (`slide_pattern`: 2 eta_a / h for the first and tip half rods, the two half rods of
      sections i-1 and i in series at a boundary).

    Both map the same way: eta_b <-> Dk / L0 and eta_a <-> De L0 (``material_damping_from_slave``), so
    hinges get N (Dk_i / L0_i + eta_b_i) / L0_i and slides `slide_pattern` of De_i + eta_a_i / L0_i.
    On the CC manifold at rest length a hinge rate is dk d / N, so the N hinges of a section dissipate
    (Dk + eta_b L0) dk^2 = the rod's eta_b d dk^2 at d = L0 (a uniform bending rate), and uniform
    extension rates dissipate (De + eta_a / L0) dd^2 (tests/test_fidelity_reference.py checks both with
    MuJoCo's own dof_damping).  Away from the manifold the material part damps every relative segment
    motion, i.e. the chain's non-CC modes too (which the q2 damping, defined only on CC rates, says
    nothing about).  The length dependence (the rod's eta_b d vs eta_b L0) is a modelled mismatch.
    (Applying -D dq2 as an explicit force instead is unstable on the light distal joints at 1 ms.)
    """
    L0 = np.asarray(slave.rest_lengths)
    eb = np.asarray(bending_viscosity, dtype=float)
    ea = np.asarray(extension_viscosity, dtype=float)
    return (hinge_values(N * (np.asarray(slave.bending_damping) / L0 + eb) / L0, layout)
            + slide_pattern(np.asarray(slave.extension_damping) + ea / L0, N, layout))


def joint_armature(slave: SlaveParams, N: int, layout: dict, fraction: float) -> np.ndarray:
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
    for the default parameters (reported separately by ``harness.studies.fidelity``).  It is needed: with
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


def servo_gains(mass_u: np.ndarray, N: int, layout: dict, frequency: float,
                damping_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Position-servo gains per chain joint (kp in N m/rad or N/m, kv in N m s/rad or N s/m), defined
    per unit length of the section so that the N servos of a section in series are N-independent.

    mass_u (6,): the section-level inertias of the CC coordinates u = [e_1..3 (kg), Theta_1..3
    (kg m^2)], the diagonal of C^T M C with M the chain's joint-space inertia at the straight rest
    configuration (armature included).  Section-level servo stiffness K_u = mass_u w^2 and damping
    D_u = 2 zeta w mass_u (w = 2 pi frequency): one CC coordinate moved alone (the others held) is a
    servo of natural frequency ``frequency`` and damping ratio ``damping_ratio``.  Distributed like the
    rod's own springs (`joint_stiffness`): every hinge of section i gets N K_Theta_i (N hinges in
    series give K_Theta_i for the section bend), the slides `slide_pattern` of K_e (N K_e_i inside a
    section, 2N K_e for the base and tip half rods, the two half rods in series at a boundary).  kv /
    kp = 2 zeta / w on every joint, so the fast local (non-CC) modes are overdamped and stable under
    implicit damping whatever their stiffness.
    """
    w = 2.0 * np.pi * float(frequency)
    mu = np.asarray(mass_u, dtype=float)
    kp_u, kv_u = mu * w * w, 2.0 * float(damping_ratio) * w * mu
    kp = hinge_values(N * kp_u[3:], layout) + slide_pattern(kp_u[:3], N, layout)
    kv = hinge_values(N * kv_u[3:], layout) + slide_pattern(kv_u[:3], N, layout)
    return kp, kv


MUSCLE_SIDES = (1.0, -1.0)  # lateral offset signs of a section's two groups: s = +r (body +x), s = -r


def muscle_tendon_coefs(N: int, layout: dict) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-tendon coefficients of the muscle fibres of each section: (slide_coef, hinge_sign), each
    (3, n_chain).  The fibre of section i at lateral offset s (m, along the body x axis, in the arm's
    plane) has length  l = sum_c slide_coef[i, c] q_c - s * sum_c hinge_sign[i, c] q_c  (+ a constant),
    the chain form of the CC fibre length l_s = d_i (1 - s k_i) = d_i - s Theta_i: a positive hinge
    angle bends the section toward +x and shortens the fibres on that side.

    Slides: 1 for the slides inside a section (j >= 1), 1 for the base half rod (slide (0, 0), all of it
    in section 0) and the tip half rod (the tip slide, in section 2); a boundary slide (i, 0), i >= 1,
    is the rod between the midpoints of the last segment of section i-1 and the first of section i:
    half of it lies in each section, so it counts 1/2 in both fibres.  On the CC manifold the fibre
    length is then d_i - s Theta_i + (e_{i+1} - e_i) / (4N) [i < 2] + (e_{i-1} - e_i) / (4N) [i > 0]
    (e = d - L0): exact when neighbouring sections extend equally, O(1/N) otherwise (a discretization
    error that vanishes as N grows).  Hinges: 1 on the hinges of section i (Theta_i = their sum).
    """
    C = layout["C"]
    n = C.shape[0]
    slide = np.zeros((3, n))
    hinge = np.zeros((3, n))
    for c in range(n):
        i, j = int(layout["section"][c]), int(layout["segment"][c])
        if layout["is_hinge"][c]:
            hinge[i, c] = 1.0
        elif j == 0 and i >= 1:
            slide[i - 1, c] = 0.5
            slide[i, c] = 0.5
        else:
            slide[i, c] = 1.0
    return slide, hinge
