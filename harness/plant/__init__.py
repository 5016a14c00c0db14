"""Plants: the MuJoCo chain, the analytic models and the Cosserat rod; `build_plant(scn)` reports
plant errors as `ConfigError` naming the scenario field.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from harness.config.errors import ConfigError, short_repr
from harness.config.scenario import Scenario

# MuJoCo body name in a compile error -> (scenario field, index): the plant's mass of that body
_BODY_FIELDS = (
    (re.compile(r"'octarm_s(\d+)_"), "plant.slave.masses"),
    (re.compile(r"'master_upper_link'"), "plant.master.masses", 0),
    (re.compile(r"'master_fore_link'"), "plant.master.masses", 1),
)


def _field_error(scn: Scenario, exc: Exception) -> ConfigError | None:
    """A plant-model error rephrased as the scenario field it comes from, if it can be located."""
    msg = " ".join(str(exc).split())
    if "mass and inertia" in msg:
        for rx, field, *idx in _BODY_FIELDS:
            m = rx.search(msg)
            if m is None:
                continue
            i = idx[0] if idx else int(m.group(1))
            robot = scn.plant_slave if field.startswith("plant.slave") else scn.plant_master
            value = np.asarray(robot.masses, dtype=float).reshape(-1)[i]
            return ConfigError(f"{field}[{i}] = {short_repr(float(value))}: too small for the plant model "
                               f"(MuJoCo: {msg})", path=field, value=float(value))
    return None


def build_plant(scn: Scenario) -> Any:
    """The plant of `scn` (`AnalyticPlant`, `MujocoPlant` or `CosseratPlant`), built and checked.
    Raises ConfigError."""
    kind = scn.plant.kind
    if kind == "analytic":
        from harness.plant.analytic import AnalyticPlant

        return AnalyticPlant(scn.plant_master, scn.plant_slave)
    if kind == "mujoco":
        from harness.plant.mujoco_model import MujocoPlant, PlantModelError

        try:
            return MujocoPlant.build(scn)
        except PlantModelError as exc:
            if exc.path is not None:
                raise ConfigError(str(exc), path=exc.path) from None
            located = _field_error(scn, exc)
            if located is not None:
                raise located from None
            if scn.plant.scene_xml is not None:
                raise ConfigError.field("plant.scene_xml", scn.plant.scene_xml,
                                        f"unusable MJCF: {exc}") from None
            raise ConfigError(f"plant: cannot build the MuJoCo model: {exc}", path="plant") from None
    if kind == "cosserat":
        from harness.plant.cosserat.plant import CosseratPlant

        return CosseratPlant(scn)
    raise ConfigError.field("plant.kind", kind, "unknown plant")


def validate_plant(scn: Scenario) -> None:
    """Build the scenario's plant once (not stepped) so that plant errors are input errors."""
    build_plant(scn)
