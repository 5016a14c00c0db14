"""The interaction-force arguments of the compiled MuJoCo loop (`mujoco_kernels.mujoco_chunk`): contact
sensors, constant tip forces, force sensing (`sensing.force`) and the operator's hand, built per run."""

from __future__ import annotations

import mujoco
import numpy as np

from controllers import master as master_model
from harness.config.scenario import Scenario
from harness.loop.force_kernels import FORCE_MODES, filter_alpha
from harness.plant.chain_map import ChainMap
from harness.plant.environment import N_POINTS, ContactMap

FORCE_NOISE_STREAM = 1  # the force noise uses its own seeded stream: default_rng([seed, 1])

class ForceArgs:
    """Arrays of one run; `args(k0, k1)`: the `fargs` of a chunk.  Applies the constant slave tip force F2
    through d.xfrc_applied on the tip body."""

    def __init__(self, scn: Scenario, m: mujoco.MjModel, d: mujoco.MjData, cmap: ChainMap,
                 contact: ContactMap | None, n: int, s0: np.ndarray, F: np.ndarray):
        fs, op = scn.sensing.force, scn.operator
        self.sensordata = d.sensordata
        self.cadr = contact.adr if contact is not None else np.zeros(0, dtype=np.int64)
        self.Fconst = np.asarray(F, dtype=float).copy()
        if self.Fconst[2] != 0.0 or self.Fconst[3] != 0.0:
            tip = m.body("octarm_tip_body").id
            d.xfrc_applied[tip, 0] = self.Fconst[2]
            d.xfrc_applied[tip, 2] = self.Fconst[3]
        self.mode = FORCE_MODES[fs.mode]
        self.noise = np.zeros((1, 4))  # standard normals (n, 4) of the force sensor, when used
        if fs.mode == "sensed" and fs.noise_std > 0.0:
            self.noise = np.random.default_rng([scn.seed, FORCE_NOISE_STREAM]).standard_normal((n, 4))
        self.std = float(fs.noise_std)
        self.alpha = filter_alpha(fs.cutoff, scn.control_dt)
        self.delay = int(round(fs.delay / scn.control_dt))
        self.buf = np.zeros((self.delay + 1, 4))
        self.filt = np.zeros(4)
        self.op_on = bool(op.enabled)
        self.op = np.array([op.mass, op.stiffness, op.damping, op.grip_stiffness, op.grip_damping])
        self.targets = np.asarray(op.targets, dtype=float).reshape(-1, 3)
        self.mpk_p = master_model.packed(scn.plant_master)
        x0 = master_model.fk(scn.plant_master, s0[0:2])
        self.hand = np.array([x0[0], x0[1], 0.0, 0.0]) if self.op_on else np.zeros(4)
        self.target = self.hand[:2].copy()
        self.cpts = np.zeros((n if contact is not None else 0, N_POINTS, 6))

    def args(self, k0: int, k1: int) -> tuple:
        """The `fargs` of steps k0..k1."""
        return (self.sensordata, self.cadr, self.Fconst, self.mode, self.noise, self.std, self.alpha,
                self.delay, self.buf, self.filt, self.op_on, self.op, self.targets, self.hand, self.target,
                self.mpk_p, self.cpts[k0:k1] if self.cpts.shape[0] else self.cpts)
