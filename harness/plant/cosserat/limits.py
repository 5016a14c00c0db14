"""Limits of the Cosserat rod's explicit stepping and what it does on faults (`CosseratSlave`).

* Stable step: `stable_dt` is a CFL-type estimate: min over sections of 2 / omega_max (axial and shear
  waves 2 c / h, c = sqrt(EA / rho A), sqrt(GA / rho A); element rotation omega^2 = GA / rho I + 4 EI /
  (rho I h^2)), reduced for the explicit extension damping by sqrt(1 + zeta^2) - zeta, times a safety
  factor 0.5 (not calibrated against measured divergence limits).
* Cost: a configuration that needs more than `MAX_STEPS_PER_CONTROL` = 1000 rod steps per control step
  (per 1 ms for the rod alone) is refused before anything runs (`check_steps_per_control`, one line).
  The default rod (10 elements per section) needs 14 rod steps per 1 ms; the step falls as 1 / n^2 with
  n elements per section once the explicit extension damping sets it: 50 elements need 254, 100 need
  1004 (refused: lower plant.extension_viscosity or use fewer elements).  At the limit one control step
  costs 1000 rod steps, about 70 times the default's (a 20-s run at 10 elements: minutes instead of
  seconds; each rod step costs more with more elements).  The limit keeps every configuration up to 50
  elements per section with a margin of 4, and refuses masses or stiffnesses off by orders of magnitude
  (a unit error: masses of 1e-6 kg need about 1e7 rod steps per control step).
* Interrupts: `step` runs its rod steps in compiled batches of at most `BATCH_STEPS`; between batches
  Python's signal handlers run (Ctrl-C) and, if `stop` (an Event, e.g. the harness's run-stop flag) is
  set after a batch, `step` raises `RodStopped` (a KeyboardInterrupt) with the state of that batch: a
  run stops within one control step of the first Ctrl-C, and a second Ctrl-C within one batch.
* Divergence: a non-finite node position, velocity or angular velocity, a node farther than
  `EXPLODING_LENGTHS` rod lengths from the base, or an arithmetic exception of the compiled step
  (ZeroDivisionError on a collapsed element, FloatingPointError, OverflowError) ends `step` with False:
  the plant reports it as a diverged run (status "diverged", with its time), never as an error.
"""

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
    """Largest explicit step (s) estimated stable for these settings (see module docstring)."""
    L0, EI, EA, GA, rhoA, rhoI = _material(params, shear_factor, rotary_radius)
    eta_a = np.broadcast_to(np.asarray(eta_a, dtype=float), (3,))
    h = L0 / elements_per_section
    w_ax = 2.0 * np.sqrt(EA / rhoA) / h
    w_sh = 2.0 * np.sqrt(GA / rhoA) / h
    w_rot = np.sqrt(GA / rhoI + 4.0 * EI / (rhoI * h * h))
    z_ax = eta_a * w_ax / (2.0 * EA)
    z_sh = eta_a * w_sh / (2.0 * GA)
    dts = np.concatenate([
        2.0 / w_ax * (np.sqrt(1 + z_ax**2) - z_ax),
        2.0 / w_sh * (np.sqrt(1 + z_sh**2) - z_sh),
        2.0 / w_rot,
    ])
    return float(SAFETY * dts.min())


def auto_dt(control_dt: float, stable: float) -> float:
    """The largest control_dt / m (m integer) that is <= stable (s)."""
    m = max(1, math.ceil(control_dt / stable))
    while control_dt / m > stable:
        m += 1
    return control_dt / m


class RodStopped(KeyboardInterrupt):
    """`CosseratSlave.step` stopped between batches because its `stop` flag is set."""


def check_steps_per_control(dt: float, control_dt: float) -> int:
    """Rod steps per control step (control_dt / dt, rounded); ValueError (one line) when it exceeds
    `MAX_STEPS_PER_CONTROL` (see the module docstring)."""
    m = max(1, round(control_dt / dt))
    if m > MAX_STEPS_PER_CONTROL:
        raise ValueError(f"plant.cosserat.dt = {float(dt)!r}: {m} rod steps of {dt:.3g} s per control step "
                         f"of {control_dt:g} s, more than the limit {MAX_STEPS_PER_CONTROL}: the sections "
                         f"are too light or too stiff for an explicit rod (check the slave masses and "
                         f"stiffnesses, elements_per_section, shear_factor, extension_viscosity)")
    return m


__all__ = ["BATCH_STEPS", "EXPLODING_LENGTHS", "MAX_STEPS_PER_CONTROL", "RodStopped", "auto_dt",
           "check_steps_per_control", "stable_dt"]
