"""MuJoCo-backed validation harness for teleoperating a redundant continuum arm (Octarm) with a
non-redundant rigid master.  Public API (see the docs, "Python API"):

    from harness import load_scenario, run, run_sweep, Trajectory

Subpackages, whose names are the architecture: `config` (typed scenario, TOML, bounds), `plant`
(MuJoCo and analytic plants), `loop` (the closed loop and its compiled kernels), `output` (Rerun
recordings, figures), `studies` (mismatch sweeps, fidelity).  Imports are lazy, so that
`import harness` stays cheap.
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
