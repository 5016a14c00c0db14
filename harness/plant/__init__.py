"""Plants: the "true" systems the controllers drive, one module per plant family.

* `harness.plant.mujoco_model`: the MuJoCo model (MJCF + MjSpec-generated Octarm chain) and
  `harness.plant.chain_map`: the chain <-> q2 maps (sensing, actuation, elastic correction);
* `harness.plant.analytic`: the paper's analytic models themselves as the plant (RK4);
* `harness.plant.cosserat_plant`: a Cosserat rod (PyElastica) slave + the rigid master, stepped from
  Python (protocol `harness.plant.stepped.SteppedPlant`).

`build_plant(scn)` builds the plant a scenario asks for; a plant validates its own inputs (scene
MJCF, compile errors) and reports them as `ConfigError` naming the scenario field, so that
`harness.config` never needs to import a plant.  The loop (`harness.loop.simulate`) takes the plant.
"""

from __future__ import annotations

from typing import Any

from harness.config.errors import ConfigError
from harness.config.scenario import Scenario


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
            if scn.plant.scene_xml is not None:
                raise ConfigError.field("plant.scene_xml", scn.plant.scene_xml,
                                        f"unusable MJCF: {exc}") from None
            raise ConfigError(str(exc), path="plant") from None
    if kind == "cosserat":
        from harness.plant.cosserat_plant import CosseratPlant

        return CosseratPlant(scn)
    raise ConfigError.field("plant.kind", kind, "unknown plant")


def validate_plant(scn: Scenario) -> None:
    """Build the scenario's plant once (not stepped) so that plant errors are input errors."""
    build_plant(scn)
