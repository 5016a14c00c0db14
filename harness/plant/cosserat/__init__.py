"""The Cosserat-rod plant (plant.kind = "cosserat"): a PyElastica rod slave and the analytic rigid master.

* `rod`: `CosseratSlave`, the planar Octarm as one Cosserat rod (model, actuation, sensing by CC fit);
* `kernels`: its compiled step (loads, position Verlet, CC fit, rest strains, active loads, contact);
* `plant`: `CosseratPlant`, the scenario's plant (protocol `harness.plant.stepped.SteppedPlant`);
* `contact`: the environment objects acting on every rod node;
* `limits`: the explicit stable step, the refused configurations, interrupts and divergence;
* `pyelastica`: the PyElastica internals the kernels call, behind a version guard.
"""

from harness.plant.cosserat.contact import NODE_RADIUS, contact_arrays
from harness.plant.cosserat.plant import CosseratPlant, rod_dt
from harness.plant.cosserat.rod import CosseratSlave, hinge_damping, material_damping_from_slave, stable_dt

__all__ = ["NODE_RADIUS", "CosseratPlant", "CosseratSlave", "contact_arrays", "hinge_damping",
           "material_damping_from_slave", "rod_dt", "stable_dt"]
