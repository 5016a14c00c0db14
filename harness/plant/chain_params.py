"""Per-joint physical parameters of the discretized Octarm chain from the slave parameters
(docs/plants.md)."""

from __future__ import annotations

import numpy as np

from controllers.params import SlaveParams

TIP_MASS_FRACTION = 1e-3  # tip body mass as a fraction of one last-section segment mass (taken from it)
TIP_SLIDE_ARMATURE = 1.0  # extra armature of the tip slide, in last-section segment masses m_2 / N


def segment_inertias(slave: SlaveParams, N: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Per-body masses (3, N) kg, inertias about y (3, N) kg m^2 (rod term, plus the slice inertia Is_i / N
    split in halves between the bodies at the segment's ends) and the tip mass kg."""
    m = np.asarray(slave.masses)
    L0 = np.asarray(slave.rest_lengths)
    Is = np.asarray(slave.slice_inertia)
    mass = np.repeat((m / N)[:, None], N, axis=1)
    iyy = mass * (L0[:, None] / N) ** 2 / 12.0
    half = (0.5 * Is / N)[:, None]
    iyy += half  # the end half of the segment's own slice inertia
    iyy[:, :-1] += half  # the start half of the next segment (same orientation as this body)
    iyy[:2, -1] += half[1:, 0]
    tip_mass = TIP_MASS_FRACTION * m[2] / N
    mass[2, N - 1] -= tip_mass
    return mass, iyy, tip_mass


def slide_pattern(per_section, N: int, layout: dict) -> np.ndarray:
    """Per-chain-joint values (0 on hinges) of a property that adds like a spring, from its per-section
    value v_i: N v_i inside a section, 2N v for the base and tip half rods, the two half rods of
    sections i-1 and i in series at a boundary, 2N v_{i-1} v_i / (v_{i-1} + v_i)."""
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


def joint_values(hinge, slide, N: int, layout: dict) -> np.ndarray:
    """Per-chain-joint values: hinge[i] (3,) on the hinges of section i, `slide_pattern` of slide (3,)."""
    h = np.asarray(hinge, dtype=float)
    return np.where(layout["is_hinge"] == 1, h[layout["section"]], 0.0) + slide_pattern(slide, N, layout)


def joint_stiffness(slave: SlaveParams, N: int, layout: dict) -> np.ndarray:
    """MuJoCo joint stiffness per chain joint (N m/rad, N/m): hinges N Kb_i / L0_i, slides
    `slide_pattern` of Ke (exact for uniform extensions; the elastic correction does the rest)."""
    L0 = np.asarray(slave.rest_lengths)
    return joint_values(N * np.asarray(slave.bending_stiffness) / L0, slave.extension_stiffness, N, layout)


def joint_damping(slave: SlaveParams, N: int, layout: dict, bending_viscosity=(0.0, 0.0, 0.0),
                  extension_viscosity=(0.0, 0.0, 0.0)) -> np.ndarray:
    """MuJoCo joint damping per chain joint (N m s/rad, N s/m), the q2 damping plus the material damping
    (eta_b, eta_a): hinges N (Dk_i / L0_i + eta_b_i) / L0_i, slides `slide_pattern` of De + eta_a / L0."""
    L0 = np.asarray(slave.rest_lengths)
    eb = np.asarray(bending_viscosity, dtype=float)
    ea = np.asarray(extension_viscosity, dtype=float)
    return joint_values(N * (np.asarray(slave.bending_damping) / L0 + eb) / L0,
                        np.asarray(slave.extension_damping) + ea / L0, N, layout)


def joint_armature(slave: SlaveParams, N: int, layout: dict, fraction: float) -> np.ndarray:
    """Joint armature per chain joint (a regularizer): ``fraction`` times m_i L0_i^2 / 3 (hinges, kg m^2)
    or m_i (slides, kg), plus TIP_SLIDE_ARMATURE m_2 / N on the tip slide."""
    sec = layout["section"]
    m, L0 = np.asarray(slave.masses)[sec], np.asarray(slave.rest_lengths)[sec]
    a = fraction * np.where(layout["is_hinge"] == 1, m * L0 ** 2 / 3.0, m)
    a[-1] += TIP_SLIDE_ARMATURE * slave.masses[2] / N
    return a


def servo_gains(mass_u: np.ndarray, N: int, layout: dict, frequency: float,
                damping_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Position-servo gains (kp, kv) per chain joint: each CC coordinate u = [e, Theta] of inertia mass_u
    (6,) = diag(C^T M C) a servo of `frequency` (Hz) and `damping_ratio`, spread like the springs."""
    w = 2.0 * np.pi * float(frequency)
    mu = np.asarray(mass_u, dtype=float)
    kp_u, kv_u = mu * w * w, 2.0 * float(damping_ratio) * w * mu
    return joint_values(N * kp_u[3:], kp_u[:3], N, layout), joint_values(N * kv_u[3:], kv_u[:3], N, layout)


MUSCLE_SIDES = (1.0, -1.0)  # lateral offset signs of a section's two groups: s = +r (body +x), s = -r


def muscle_tendon_coefs(N: int, layout: dict) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-tendon coefficients (slide_coef, hinge_sign), each (3, n_chain), of section i's fibre at
    offset s: l = slide_coef[i] . q - s hinge_sign[i] . q, the chain form of d_i - s Theta_i.  A
    boundary slide counts 1/2 in both sections (O(1/N) off when neighbours extend unequally)."""
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
