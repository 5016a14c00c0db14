"""MuJoCo-backed validation harness for teleoperating a redundant continuum arm (Octarm) with a rigid
master.  Public API (docs, "Python API"): ``from harness import load_scenario, run, run_sweep, Trajectory``.
Subpackages, in layers: `config` < `plant` < `loop` < `output` < `studies` < `api`/`cli`; imports are lazy.
"""

from __future__ import annotations

__all__ = ["Trajectory", "load_scenario", "run", "run_sweep"]


def __getattr__(name: str):
    if name in ("load_scenario", "run", "run_sweep"):
        from harness import api

        return getattr(api, name)
    if name == "Trajectory":
        from harness.loop.trajectory import Trajectory

        return Trajectory
    raise AttributeError(f"module 'harness' has no attribute {name!r}")
