"""Limits of the Cosserat rod's explicit stepping (`stable_dt`, refused configurations, interrupts,
divergence); docs/plants.md, "The Cosserat rod's model"."""

from __future__ import annotations

import math

import numpy as np

from controllers.params import SlaveParams
from harness.config.scenario import CosseratConfig, PlantConfig

MAX_STEPS_PER_CONTROL = 1000  # rod steps per control step above which a configuration is refused
BATCH_STEPS = 500  # rod steps per compiled call between interrupt / stop checks (about 10 ms)
EXPLODING_LENGTHS = 10.0  # a node farther than this many rod lengths from the base: diverged
SAFETY = 0.5  # stable_dt's factor on the CFL-type estimate
# the scenario's defaults (harness.config.scenario declares them once)
DEFAULT_ELEMENTS = CosseratConfig.elements_per_section
DEFAULT_ETA_A = PlantConfig.extension_viscosity[0]  # N s, extension viscosity per section
DEFAULT_ETA_B = PlantConfig.bending_viscosity[0]  # N m^2 s, bending viscosity per section
DEFAULT_SHEAR_FACTOR = CosseratConfig.shear_factor  # docs/rod-convergence.md
DEFAULT_ROTARY_RADIUS = CosseratConfig.rotary_radius  # m


def _material(params: SlaveParams, shear_factor: float, rotary_radius: float):
    L0 = np.asarray(params.rest_lengths, dtype=float)
    EI = np.asarray(params.bending_stiffness, dtype=float)
    EA = np.asarray(params.extension_stiffness, dtype=float) * L0
    rhoA = np.asarray(params.masses, dtype=float) / L0
    si = np.asarray(params.slice_inertia, dtype=float)
    rhoI = np.where(si > 0, si, rhoA * rotary_radius**2 / 4.0)
    return L0, EI, EA, shear_factor * EA, rhoA, rhoI


def stable_dt(params: SlaveParams, elements_per_section: int = DEFAULT_ELEMENTS,
              shear_factor: float = DEFAULT_SHEAR_FACTOR, rotary_radius: float = DEFAULT_ROTARY_RADIUS,
              eta_a=DEFAULT_ETA_A) -> float:
    """Largest explicit step (s) estimated stable for these settings (docs/plants.md)."""
    L0, EI, EA, GA, rhoA, rhoI = _material(params, shear_factor, rotary_radius)
    eta_a = np.broadcast_to(np.asarray(eta_a, dtype=float), (3,))
    h = L0 / elements_per_section
    w_ax = 2.0 * np.sqrt(EA / rhoA) / h
    w_sh = 2.0 * np.sqrt(GA / rhoA) / h
    w_rot = np.sqrt(GA / rhoI + 4.0 * EI / (rhoI * h * h))
    z_ax = eta_a * w_ax / (2.0 * EA)
    z_sh = eta_a * w_sh / (2.0 * GA)
    dts = (2.0 / w_ax * (np.sqrt(1 + z_ax**2) - z_ax), 2.0 / w_sh * (np.sqrt(1 + z_sh**2) - z_sh),
           2.0 / w_rot)
    return float(SAFETY * min(x.min() for x in dts))


def auto_dt(control_dt: float, stable: float) -> float:
    """The largest control_dt / m (m integer) that is <= stable (s); ValueError unless stable is finite
    and > 0."""
    if not (math.isfinite(stable) and stable > 0.0):
        raise ValueError(f"plant.cosserat: stable time step {stable!r} s is not a finite number > 0")
    m = max(1, math.ceil(control_dt / stable))
    while control_dt / m > stable:
        m += 1
    return control_dt / m


class RodStopped(KeyboardInterrupt):
    """`CosseratSlave.step` stopped between batches because its `stop` flag is set."""


def check_steps_per_control(dt: float, control_dt: float) -> int:
    """Rod steps per control step (control_dt / dt, rounded); ValueError (one line) when it exceeds
    `MAX_STEPS_PER_CONTROL`."""
    m = max(1, round(control_dt / dt))
    if m > MAX_STEPS_PER_CONTROL:
        raise ValueError(f"plant.cosserat.dt = {float(dt)!r}: {m} rod steps of {dt:.3g} s per control step "
                         f"of {control_dt:g} s, more than the limit {MAX_STEPS_PER_CONTROL}: the sections "
                         f"are too light or too stiff for an explicit rod (check the slave masses and "
                         f"stiffnesses, elements_per_section, shear_factor, extension_viscosity)")
    return m


__all__ = ["BATCH_STEPS", "EXPLODING_LENGTHS", "MAX_STEPS_PER_CONTROL", "RodStopped", "auto_dt",
           "check_steps_per_control", "stable_dt"]
