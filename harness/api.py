"""The public Python API (also what `teleop` is built on).

    from harness import load_scenario, run, Trajectory, run_sweep

    scn = load_scenario("scenarios/paper.toml", ["duration=5", "plant.slave.masses=[1.2,0.84,0.48]"])
    traj = run(scn)                       # in-memory Trajectory; traj.meta["metrics"] has the metrics
    traj = run(scn, out="runs/mine")      # ... and writes run.rrd, figures, metrics.json, config.toml
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from harness.config import load as _load
from harness.config.errors import ConfigError
from harness.config.runtime import options
from harness.config.scenario import Scenario
from harness.config.textio import jsonable, prepare_out_dir, write_atomic

Source = Scenario | str | os.PathLike | Mapping | None


def load_scenario(source: str | os.PathLike | Mapping | None = None, overrides: Iterable[str] = (), *,
                  labels: Iterable[str | None] | None = None, allow_code: bool | None = None,
                  controller: bool = True) -> Scenario:
    """Read and validate a scenario (TOML path, parsed table or None = the paper scenario) with the dotted
    `key=value` overrides, and build its plant (kept for the next `run_scenario` of it).  Raises
    `ConfigError`.  allow_code=True: a scenario FILE may name a Python controller ('file.py:Class');
    controller=False: the controller is not loaded (no code is imported)."""
    from harness.config.controller import resolve_controller
    from harness.plant import build_plant

    scn = _load.load_scenario(source, overrides, labels=labels, allow_code=allow_code if controller else True)
    plant = build_plant(scn)
    if not controller:
        return scn
    scn = resolve_controller(scn)
    _BUILT[:] = [(scn, plant)]
    return scn


# the plant `load_scenario` built for its check, used once by `run_scenario` of that very scenario object
_BUILT: list[tuple[Scenario, Any]] = []


def _scenario_of(scenario: Source, overrides: Iterable[str], allow_code: bool | None = None) -> Scenario:
    """A validated scenario with its controller resolved, from a `Scenario` or what `load_scenario` takes."""
    if not isinstance(scenario, Scenario):
        return load_scenario(scenario, overrides, allow_code=allow_code)
    if overrides:
        raise TypeError("overrides apply to a scenario file or table, not to a Scenario object")
    if _BUILT and _BUILT[0][0] is scenario:  # from `load_scenario`: checked, its plant kept
        return scenario
    return load_scenario(_load.scenario_to_dict(scenario), allow_code=True)  # a file's checks, every field


@dataclass
class RunResult:
    """`run_scenario`'s trajectory, metrics (None: not computed), files written, outputs not produced
    (one line each) and whether a signal interrupted the run."""

    traj: Any
    metrics: dict | None
    written: list[Path]
    failures: list[str]
    interrupted: bool


@contextlib.contextmanager
def stop_on_signals(stop: threading.Event | None) -> Iterator[list[int]]:
    """While active, SIGINT/SIGTERM set `stop` (the run ends "interrupted"); a second one, or the first while
    a Python controller's code runs, raises `HarnessInterrupt`.  Yields the received signal numbers."""
    received: list[int] = []
    if stop is None or threading.current_thread() is not threading.main_thread():
        yield received
        return
    from harness.config.controller import USER_CODE, HarnessInterrupt

    def handler(signum, frame):  # noqa: ARG001
        if stop.is_set():
            raise HarnessInterrupt
        received.append(signum)
        stop.set()
        print(f"\n{signal.Signals(signum).name}: stopping the run, outputs will be written "
              "(repeat to abort immediately)", file=sys.stderr)
        if USER_CODE[0]:  # a controller's code is running (it may block): stop it now
            raise HarnessInterrupt

    stop.clear()
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield received
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
        stop.clear()


def tool_info() -> dict[str, str]:
    """metrics.json's "tool": package name, version and git revision (each absent when unknown)."""
    from harness.config.runtime import DIST_NAME, provenance

    return {"name": DIST_NAME, **provenance()}


def write_config(scn: Scenario, path: Path) -> Path:
    """config.toml: the resolved scenario (`load_scenario(path) == scn`) under a comment naming the tool."""
    info = tool_info()
    what = " ".join([info["name"], *([info["version"]] if "version" in info else []),
                     *([f"(git {info['git_revision']})"] if "git_revision" in info else [])])
    return write_atomic(path, f"# written by {what}\n" + _load.dumps_scenario(scn))


# drawn by a forked child while this process draws the rest and a third one writes run.rrd (about half
# the drawing each, measured by benchmarks/bench_core.py)
FIGURES_IN_CHILD = ("fig2_e1.png", "fig3_e2.png", "fig4_beta.png", "forces.png")


def run_scenario(scn: Scenario, out: Path | None = None, progress: bool = False, *,
                 handle_signals: bool = False, on_chunk: Callable | None = None,
                 record_rate: float | None = None) -> RunResult:
    """Simulate, compute metrics and (if `out`) write every output that can be written (docs: "Outputs and
    their guarantees").  Raises OutputError if the folder cannot be cleared or config.toml cannot be
    written (nothing ran).  handle_signals: SIGINT/SIGTERM stop the run cleanly; on_chunk: as
    `harness.loop.simulate`'s; record_rate: Hz of the 3-D geometry in run.rrd (None: the default)."""
    from harness import loop
    from harness.config.textio import remove_outputs
    from harness.loop import common
    from harness.loop.metrics import compute_metrics
    from harness.output import FIGURES
    from harness.plant import build_plant

    failures: list[str] = []
    failed: list[str] = []

    def attempt(what: str, fn: Callable[[], Any]) -> Any:
        try:
            return fn()
        except Exception as e:  # noqa: BLE001 - write whatever else exists, report below
            if options().debug:  # TELEOP_DEBUG=1
                traceback.print_exc()
            failures.append(f"{what}: {' '.join(str(e).split())}" if isinstance(e, ConfigError)
                            else f"{what}: {type(e).__name__}: {e}")
            failed.append(what)
        return None

    plant = _BUILT.pop()[1] if _BUILT and _BUILT[0][0] is scn else build_plant(scn)
    written: list[Path] = []
    if out is not None:  # a reused folder's previous outputs go; then the configuration, whatever follows
        names = ["config.toml", "run.rrd", "metrics.json", *FIGURES]
        with contextlib.suppress(OSError, ValueError, TypeError, AttributeError):  # those it lists
            prev = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
            names += [n for n in prev.get("outputs", []) if isinstance(n, str) and Path(n).name == n]
        remove_outputs(out, names)
        written.append(write_config(scn, out / "config.toml"))
    with stop_on_signals(common.STOP if handle_signals else None) as received:
        traj = loop.simulate(scn, plant=plant, progress=progress, on_chunk=on_chunk)
    interrupted = bool(received) or traj.status == "interrupted"

    metrics = attempt("metrics", lambda: dict(compute_metrics(traj, scn)))
    failed.clear()  # metrics are not a file
    if metrics is not None:
        metrics.setdefault("status", traj.status)
        metrics.setdefault("message", traj.message)
        traj.meta["metrics"] = metrics
    if out is not None:
        doc = metrics if metrics is not None else {"status": traj.status, "message": traj.message,
                                                    "metrics_error": failures[-1] if failures else ""}
        written += _write_outputs(traj, out, record_rate, attempt)

        def write_metrics() -> Path:
            final = dict(doc, tool=tool_info(), outputs=[p.name for p in written] + ["metrics.json"],
                         outputs_failed=list(dict.fromkeys(failed)), output_errors=list(failures))
            return write_atomic(out / "metrics.json", json.dumps(jsonable(final), indent=2, allow_nan=False)
                                + "\n")

        res = attempt("metrics.json", write_metrics)
        if res is not None:
            written.append(res)
    return RunResult(traj, metrics, written, failures, interrupted)


def _write_outputs(traj: Any, out: Path, record_rate: float | None, attempt: Callable) -> list[Path]:
    """run.rrd and the figures at the same time: the recording in a forked child, FIGURES_IN_CHILD in a
    second one, the other figures here (`harness.output.guarded.start_in_child`).  Each failure goes
    through `attempt`; returns the paths written (run.rrd, then the figures in FIGURES order)."""
    from harness.output import FIGURES, plots, record
    from harness.output.guarded import start_in_child

    traj.meta["geometry_rate"] = record.DEFAULT_GEOMETRY_RATE if record_rate is None else float(record_rate)
    names = attempt("figures", lambda: plots.figure_names(traj)) or []
    theirs = [n for n in names if n in FIGURES_IN_CHILD]
    mine = [n for n in names if n not in theirs]
    children = []
    written: dict[str, Path] = {}
    try:
        rec = attempt("run.rrd", lambda: start_in_child(lambda: record.write_recording(traj, out / "run.rrd"),
                                                        out / "run.rrd"))
        fig = None
        if theirs:
            fig = attempt("figures", lambda: start_in_child(
                lambda: plots.write_figures(traj, out, names=theirs), out / theirs[0], stall_timeout=None,
                others=[out / n for n in theirs[1:]]))
        children = [c for c in (rec, fig) if c is not None]
        # what each drawer wrote, even if it then failed: complete files only (atomic renames)
        if mine:
            attempt("figures", lambda: plots.write_figures(traj, out, names=mine))
        if fig is not None:
            attempt("figures", fig.wait)
        written.update((n, out / n) for n in names if (out / n).is_file())
        if rec is not None and attempt("run.rrd", rec.wait) is not None:
            written["run.rrd"] = out / "run.rrd"
    finally:
        for child in children:
            child.kill()
    return [written[n] for n in ("run.rrd", *FIGURES) if n in written]


def run(scenario: Source = None, overrides: Iterable[str] = (), *, out: str | os.PathLike | None = None,
        progress: bool = False, allow_code: bool | None = None):
    """Run a scenario and return its `Trajectory` (metrics in `traj.meta["metrics"]`).

    scenario: a `Scenario`, a TOML path, a parsed table, or None (the paper scenario on MuJoCo);
    overrides: dotted `key=value` strings (not with a `Scenario`).  out: folder for run.rrd, figures,
    metrics.json and config.toml (None = write nothing).  allow_code: as `load_scenario`'s.  Raises
    `ConfigError` for bad input, `RuntimeError` (with the trajectory as `traj`) if an output failed."""
    scn = _scenario_of(scenario, overrides, allow_code)
    res = run_scenario(scn, prepare_out_dir(out) if out is not None else None, progress)
    if res.failures:
        err = RuntimeError("could not produce: " + "; ".join(res.failures))
        err.traj = res.traj  # type: ignore[attr-defined]
        raise err
    return res.traj


def run_sweep(study, out=None, **kwargs):
    """Run a mismatch study (`harness.studies.sweep.run_sweep`; allow_code=True lets a study file name
    Python controllers)."""
    from harness.studies.sweep import run_sweep as _run_sweep

    return _run_sweep(study, out, **kwargs)


def stability(scenario: Source = None, overrides: Iterable[str] = (), *, t: float = 1.0,
              h: float | None = None, out: str | os.PathLike | None = None):
    """Linear stability of the sampled-data closed loop at time t (s), as `teleop stability` (relative
    central-difference step h; out: folder of its files): `harness.studies.stability.Stability`.  Raises
    `ConfigError` for bad input, `harness.studies.stability.LinearizationError` if the run stops before t."""
    from harness.studies.stability import linearize
    from harness.studies.stability_report import write_stability

    if not (isinstance(t, (int, float)) and math.isfinite(t) and 0.0 <= t <= 3600.0):
        raise ConfigError.field("t", t, "expected a time in s in [0, 3600]")
    if h is not None and not (isinstance(h, (int, float)) and 0.0 < h < 1e-2):
        raise ConfigError.field("h", h, "expected a finite-difference step in (0, 0.01)")
    res = linearize(_scenario_of(scenario, overrides), float(t), h)
    if out is not None:
        write_stability(res, prepare_out_dir(out))
    return res


def margins(scenario: Source = None, overrides: Iterable[str] = (), *, bounds,
            params: Iterable[str] | None = None, rtol: float = 0.05, probes: int = 2,
            out: str | os.PathLike | None = None, workers: int | None = None, scheduler: str | None = None,
            executor: str = "processes", pair: tuple[str, str] | None = None, n_rays: int = 8,
            say: Callable[[str], None] = lambda s: None):
    """Robustness margins of a scenario against bounds (path, table or `Bounds`), as `teleop margin`
    (params: default `harness.studies.margin.DEFAULT_PARAMS`).  Returns (rows, edge rows or None).
    Raises `ConfigError` for bad input or a nominal scenario that fails the bounds."""
    from harness.config.bounds import Bounds, load_bounds
    from harness.studies import margin as mg
    from harness.studies import margin_report as mr

    scn = _scenario_of(scenario, overrides)
    b = bounds if isinstance(bounds, Bounds) else load_bounds(bounds)
    if not (isinstance(probes, int) and 0 <= probes <= 10):
        raise ConfigError.field("probes", probes, "expected an integer in [0, 10]")
    out_dir = prepare_out_dir(out) if out is not None else None
    # the cases: this scenario + one override per parameter
    if isinstance(scenario, Scenario):
        source, base = _load.scenario_to_dict(scn), []
    else:
        source, base = scenario, list(overrides)
    kw = dict(source=source, base_set=base, rtol=rtol, probes=probes, out=out_dir, workers=workers,
              scheduler=scheduler, executor=executor, say=say)
    names = list(params) if params is not None else list(mg.DEFAULT_PARAMS)
    rows = mg.margins(scn, b, names, **kw) if names else []
    edge = mg.edge_trace(scn, b, tuple(pair), n_rays, **kw) if pair is not None else None
    if out_dir is not None:
        if rows:
            tol = (f"tolerance: scale factors to {rtol:g} relative (fail / pass - 1), values to 1/100 of the "
                   f"range, delay to one control period, integers exactly; {probes} probe(s) per side")
            if note := mg.servo_note(scn, names):
                tol += f"\n\nwarning: {note}"
            mr.write_margins(rows, out_dir, tol)
        if edge is not None:
            (out_dir / "edge.json").write_text(json.dumps(jsonable(edge), indent=2) + "\n", encoding="utf-8")
            mr.plot_edge(edge, tuple(pair), out_dir / "edge.png")
    return rows, edge
