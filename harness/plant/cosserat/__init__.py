"""The Cosserat-rod plant (plant.kind = "cosserat"): a PyElastica rod slave (`rod`, compiled step `kernels`,
`limits`, `contact`, PyElastica internals behind a version guard in `pyelastica`) and the analytic rigid
master (`plant.CosseratPlant`)."""

from harness.plant.cosserat.contact import NODE_RADIUS, contact_arrays
from harness.plant.cosserat.plant import CosseratPlant, rod_dt
from harness.plant.cosserat.rod import CosseratSlave, material_damping_from_slave, stable_dt

__all__ = ["NODE_RADIUS", "CosseratPlant", "CosseratSlave", "contact_arrays",
           "material_damping_from_slave", "rod_dt", "stable_dt"]
