"""`teleop` command-line interface.

    teleop run [SCENARIO.toml] [options]                    simulate one scenario, write outputs
    teleop check [SCENARIO.toml] --bounds BOUNDS.toml ...    simulate and check acceptance bounds
    teleop models [SCENARIO.toml] [--segments N] ...         export the generated MuJoCo model (MJCF)
    teleop sweep STUDY.toml [--out DIR] [--workers N] ...    parameter sweep (local or Dask cluster)
    teleop controllers                                       list the built-in controllers
    teleop fidelity [--segments 4,8,16,32] [--samples N] [--reference analytic|cosserat]   plant fidelity

Exit status: 0 success; 1 the run failed (diverged, an output could not be written) or a bound was
violated; 2 invalid input (scenario, bounds, option, output folder; a file that cannot be written before
anything ran); 130 interrupted (SIGINT/SIGTERM).
Invalid input is reported as a single ``error: ...`` line on stderr, never a traceback.

The simulation back ends are imported lazily so that ``--help`` and input validation are fast.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import os
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from controllers.params import ParameterError
from harness.config.errors import ConfigError
from harness.config.scenario import ACTUATIONS, PLANTS
from harness.config.textio import jsonable, prepare_out_dir

EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130

# (module, attribute) of exception types that mean "invalid input" (exit 2).  Looked up in
# sys.modules only: if the module was never imported, its exception cannot have been raised.
_USER_ERRORS = (
    ("harness.plant.mujoco_model", "PlantModelError"),
    ("harness.loop.common", "SimulationError"),
)


def _user_error_types() -> tuple[type[BaseException], ...]:
    out: list[type[BaseException]] = [ConfigError, ParameterError]
    for mod_name, attr in _USER_ERRORS:
        cls = getattr(sys.modules.get(mod_name), attr, None)
        if isinstance(cls, type) and issubclass(cls, BaseException):
            out.append(cls)
    return tuple(out)


def _one_line(text: Any) -> str:
    return " ".join(str(text).split()) or "(no message)"


def _err(msg: Any) -> None:
    print(f"error: {_one_line(msg)}", file=sys.stderr)


def _warn(msg: Any) -> None:
    print(f"warning: {_one_line(msg)}", file=sys.stderr)


# ---------------------------------------------------------------------------------------------
# argument parsing
# ---------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one `error: ...` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"error: {self.prog}: {_one_line(message)} (see '{self.prog} --help')\n")


class _Formatter(argparse.HelpFormatter):
    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=32, width=100)


def _int_at_least(lo: int) -> Callable[[str], int]:
    """argparse type: an integer >= lo."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"expected an integer >= {lo}, got {v}")
        return v

    return parse


_positive_int, _nonnegative_int = _int_at_least(1), _int_at_least(0)


def _path(text: str) -> Path:
    """A path argument; the empty string is rejected (Path('') would silently mean '.')."""
    if not str(text).strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return Path(text)


def _add_scenario_options(p: argparse.ArgumentParser, *, sim: bool = True) -> None:
    p.add_argument(
        "scenario", nargs="?", metavar="SCENARIO.toml", default=None,
        help="scenario file (layout: scenarios/paper.toml). Default: the built-in paper scenario "
             "(the same values as scenarios/paper.toml, which spells every one of them out).")
    if sim:
        p.add_argument("--plant", choices=PLANTS, default=None,
                       help="plant that is simulated: 'mujoco' (MuJoCo multibody model), 'analytic' "
                            "(RK4 on the analytic model) or 'cosserat' (PyElastica Cosserat rod). "
                            "Shortcut for --set plant.kind=... "
                            "Default: from the scenario (paper: mujoco).")
    p.add_argument("--actuation", choices=ACTUATIONS, default=None,
                   help="MuJoCo slave actuation: 'servo' (segment-joint position servos) or 'torque' "
                        "(generalized forces mapped to joint torques). "
                        "Shortcut for --set plant.actuation=... "
                        "Default: from the scenario (paper: servo).")
    p.add_argument("--segments", metavar="N", default=None,
                   help="rigid segments per slave section in the MuJoCo model, integer in [1, 64]. "
                        "Shortcut for --set plant.segments=N. Default: from the scenario (paper: 8).")
    if sim:
        p.add_argument("--duration", metavar="S", default=None,
                       help="simulated time in seconds, in (0, 3600]. It must exceed the transient after "
                            "which metrics are taken (scenario key 'transient', paper: 5 s); when the "
                            "scenario does not set it, runs of 5 s or less use duration / 4. A scenario file "
                            "that sets it (e.g. scenarios/paper.toml) needs --set transient=... for shorter "
                            "runs. Default: from the scenario (paper: 20).")
        p.add_argument("--controller", metavar="NAME|FILE.py:CLASS", default=None,
                       help="controller: a built-in name ('teleop controllers' lists them; 'paper' = the "
                            "paper's law, compiled), 'path/to/file.py:ClassName' or "
                            "'package.module:ClassName' (controllers/interface.py). Shortcut for --set "
                            "controller.name=...; its parameters: --set controller.params.KEY=VALUE. "
                            "Default: from the scenario (paper: paper).")
        p.add_argument("--seed", metavar="N", default=None,
                       help="noise seed, integer >= 0. Default: from the scenario (paper: 0).")
        p.add_argument("--snr", metavar="DB|none", default=None,
                       help="signal-to-noise ratio of the AWGN on the fed-back states in dB, in [0, 200], or "
                            "'none' for no noise. Default: from the scenario (paper: 40).")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override any scenario field by its dotted key; VALUE is a TOML value "
                        "(e.g. plant.segments=16, plant.slave.masses=[1.2,0.7,0.4], snr_db=30, "
                        "plant.kind=analytic). Repeatable; applied in order after the shortcut options.")


def _record_rate(text: str) -> float:
    """argparse type of --record-rate: a rate in Hz > 0, or 'full' (every control step)."""
    if str(text).strip().lower() == "full":
        return math.inf
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a rate in Hz > 0 or 'full', got {text!r}")
    return v


def _add_record_rate(p: argparse.ArgumentParser) -> None:
    p.add_argument("--record-rate", metavar="HZ|full", type=_record_rate, default=None,
                   help="rate of the 3-D geometry (arms, segments, backbone) in run.rrd, Hz > 0, or 'full' "
                        "for every control step; the time series are always written at the control rate. "
                        "Default: 100 (chosen by measurement, see README 'Speed').")


def _add_out_and_progress(p: argparse.ArgumentParser, out_help: str) -> None:
    p.add_argument("--out", metavar="DIR", type=_path, default=None, help=out_help)
    p.add_argument("--no-progress", action="store_true",
                   help="do not show the progress bar (default: shown on stderr).")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="teleop", formatter_class=_Formatter,
        description="Validation harness for teleoperating a continuum arm (Octarm) with a 2-link "
                    "rigid master.",
        epilog="exit status: 0 ok; 1 run failed (diverged, outputs not written) or bounds violated; "
               "2 invalid input; 130 interrupted (SIGINT/SIGTERM). "
               "Set TELEOP_DEBUG=1 to print tracebacks of output-writing failures. "
               "Run 'teleop COMMAND --help' for the options of each command.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}",
                        help="print the package version and exit.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")

    run = sub.add_parser(
        "run", formatter_class=_Formatter, help="simulate one scenario and write its outputs",
        description="Load and validate a scenario, simulate it and write into the output folder: "
                    "config.toml (fully resolved scenario, written before simulating), metrics.json, "
                    "run.rrd (Rerun recording) and the PNG figures. Outputs are written even when the run "
                    "diverges or is interrupted (Ctrl-C / SIGTERM stop the run cleanly; a second Ctrl-C "
                    "aborts).",
        epilog="exit status: 0 ok; 1 diverged / outputs not written; 2 invalid input; 130 interrupted.")
    _add_scenario_options(run)
    _add_out_and_progress(run, "output folder (created; must be writable). Default: runs/<scenario name>.")
    run.add_argument("--view", nargs="?", const="native", choices=("native", "web"), default=None,
                     help="stream the run to a Rerun viewer while it is simulated: 'native' (the default "
                          "with a bare --view) spawns the viewer, 'web' serves Rerun's web viewer and waits "
                          "for Ctrl-C after the run. run.rrd is written as without it. Default: no viewer.")
    _add_record_rate(run)
    run.set_defaults(func=cmd_run)

    check = sub.add_parser(
        "check", formatter_class=_Formatter, help="simulate a scenario and check acceptance bounds",
        description="Like 'run', then compare the metrics with a bounds file and list every violated bound "
                    "with its measured value and limit. Outputs are written only with --out.",
        epilog="exit status: 0 all bounds satisfied; 1 a bound is violated (or the run failed); "
               "2 invalid input; 130 interrupted.")
    _add_scenario_options(check)
    check.add_argument("--bounds", metavar="BOUNDS.toml", type=_path, required=True,
                       help="bounds file (required; layout: bounds/paper_mujoco.toml).")
    _add_out_and_progress(check, "also write the run outputs (as 'run' does) into this folder. "
                                 "Default: no files are written.")
    _add_record_rate(check)
    check.set_defaults(func=cmd_check)

    models = sub.add_parser(
        "models", formatter_class=_Formatter, help="export the generated MuJoCo model (MJCF)",
        description="Write the MJCF of the plant (plant master and plant slave of the scenario, i.e. with "
                    "any [plant.master]/[plant.slave] mismatch) via harness.plant.mujoco_model.export_mjcf.")
    _add_scenario_options(models, sim=False)
    models.add_argument("--enforce-cc", action=argparse.BooleanOptionalAction, default=None,
                        help="with / without the equality constraints holding each section at constant "
                             "curvature (sets plant.enforce_cc). Default: from the scenario (paper: false).")
    models.add_argument("--out", metavar="FILE.xml", type=_path, default=None,
                        help="output MJCF file (parent folders are created). "
                             "Default: mjcf/octarm_<actuation>_n<segments>[_cc].xml.")
    models.set_defaults(func=cmd_models)

    sweep = sub.add_parser(
        "sweep", formatter_class=_Formatter, help="run a parameter sweep (study file)",
        description="Run every case of a study file (harness.studies.sweep) in local worker processes or "
                    "on a Dask cluster. Each finished case is appended to results.jsonl as it finishes; "
                    "re-running the same command resumes (finished cases are skipped). Also written: "
                    "summary.csv, metric plots (lines for 1-D factors, heatmaps for 2-D grids), "
                    "study.toml (resolved) and optional recordings of the worst cases.",
        epilog="study file (TOML; see studies/*.toml and the README): [study] name, scenario (base "
               "scenario file), set (overrides for every case), metrics, record = {worst = k, by = METRIC}; "
               "[[factor]] param = any scenario key (e.g. plant.slave.masses[0]) with scale = [...] "
               "(x nominal), values = [...] or scale/values = {random = 'uniform', low, high}; "
               "[sampling] mode = 'grid' | 'random', n, seed. "
               "exit status: 0 every case has a row (diverged cases are rows too); 1 cases unfinished or "
               "the executor failed; 2 invalid study, option or output folder; 130 interrupted (re-run to "
               "resume).")
    sweep.add_argument("study", metavar="STUDY.toml", type=_path, help="study file describing the sweep.")
    sweep.add_argument("--out", metavar="DIR", type=_path, default=None,
                       help="output folder (created; must be writable; an existing sweep folder is "
                            "resumed). Default: runs/sweeps/<study name>.")
    sweep.add_argument("--workers", metavar="N", type=_positive_int, default=None,
                       help="number of local worker processes, integer >= 1 (ignored with --scheduler). "
                            f"Default: all cores ({os.cpu_count() or 1} here).")
    sweep.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="address of a running Dask scheduler (e.g. tcp://host:8786) to run on a "
                            "cluster. Default: none (local processes).")
    sweep.add_argument("--max-cases", metavar="N", type=_positive_int, default=None,
                       help="refuse a study with more than N cases, checked before the cases are built "
                            "(replaces the study's [sampling] max_cases). "
                            "Default: from the study, else 10000.")
    sweep.add_argument("--no-progress", action="store_true",
                       help="do not show the progress bar (default: shown on stderr).")
    sweep.add_argument("--view", metavar="CASE_ID", default=None,
                       help="do not run: open the recording of case CASE_ID of this sweep "
                            "(<out>/recordings/CASE_ID.rrd, written for the worst cases, see record) in a "
                            "Rerun viewer. Default: run the sweep.")
    sweep.set_defaults(func=cmd_sweep)

    ctl = sub.add_parser(
        "controllers", formatter_class=_Formatter, help="list the built-in controllers",
        description="List the built-in controllers (name, supported plant actuations, one-line description). "
                    "Your own: --controller path/to/file.py:ClassName (README 'Bring your own controller').",
        epilog="Default controller of every scenario: paper (the paper's laws on the compiled fast path).")
    ctl.set_defaults(func=cmd_controllers)

    fid = sub.add_parser(
        "fidelity", formatter_class=_Formatter, help="plant-fidelity study over MuJoCo segment counts",
        description="Compare the generated MuJoCo Octarm with N rigid segments per section against the "
                    "analytic constant-curvature model (tip position, Jacobian, inertia, gravity, elastic "
                    "forces at seeded random configurations; plus the master) for several N, with the "
                    "observed convergence order, and the same chain with and without the constant-curvature "
                    "equality constraints (shape held under gravity, mj_step cost, closed loop) "
                    "(harness.studies.fidelity). Writes fidelity.md, fidelity.csv, fidelity.png, "
                    "fidelity_cc.md and fidelity_cc.csv.")
    fid.add_argument("--segments", metavar="N,N,...", default="4,8,16,32",
                     help="comma-separated segment counts per section, each an integer in [1, 64]. "
                          "Default: 4,8,16,32.")
    fid.add_argument("--samples", metavar="N", type=_positive_int, default=50,
                     help="random in-range slave configurations for the discretization table, integer >= 1. "
                          "Default: 50.")
    fid.add_argument("--seed", metavar="N", type=_nonnegative_int, default=0,
                     help="seed of the random configurations, integer >= 0. Default: 0.")
    fid.add_argument("--reference", choices=("analytic", "cosserat"), default="analytic",
                     help="analytic: the discretization and CC tables against the analytic model; cosserat: "
                          "the analytic CC model and the chain (CC on/off, each N) against the Cosserat rod "
                          "(statics, small motion, closed loop; harness.studies.fidelity_reference). "
                          "Default: analytic.")
    fid.add_argument("--out", metavar="DIR", type=_path, default=Path("runs/fidelity"),
                     help="output folder (created; must be writable). Default: runs/fidelity.")
    fid.add_argument("--no-progress", action="store_true",
                     help="do not show progress output (default: shown on stderr when available).")
    fid.set_defaults(func=cmd_fidelity)
    return parser


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("octarm-teleop")
    except Exception:  # noqa: BLE001 - not installed: version unknown
        return "unknown"


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
_SHORTCUTS = (  # (attribute, option, dotted key)
    ("plant", "--plant", "plant.kind"),
    ("actuation", "--actuation", "plant.actuation"),
    ("segments", "--segments", "plant.segments"),
    ("duration", "--duration", "duration"),
    ("controller", "--controller", "controller.name"),
    ("seed", "--seed", "seed"),
    ("snr", "--snr", "snr_db"),
)


def load_from_args(args: argparse.Namespace, extra: Sequence[tuple[str, str]] = ()):
    """Scenario from the positional file, the shortcut options, `extra` (key=value, label) and --set."""
    from harness.api import load_scenario

    overrides: list[str] = []
    labels: list[str | None] = []
    for attr, option, key in _SHORTCUTS:
        value = getattr(args, attr, None)
        if value is not None:
            text = str(value).strip()
            if key in ("plant.kind", "plant.actuation", "controller.name"):
                text = json.dumps(text)  # always a TOML string
            overrides.append(f"{key}={text}")
            labels.append(f"{option} {value}")
    for text, label in extra:
        overrides.append(text)
        labels.append(label)
    for text in args.overrides:
        overrides.append(text)
        labels.append(f"--set {text if len(text) <= 80 else text[:77] + '...'}")
    return load_scenario(args.scenario, overrides, labels=labels)


def _import(name: str):
    """Import a harness back end lazily; a missing module is reported as one line (exit 1)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as e:
        if e.name and (name == e.name or name.startswith(e.name + ".")):
            raise _Unavailable(f"{name} is not available ({e})") from None
        raise


class _Unavailable(RuntimeError):
    """A lazily imported back end (simulation, plotting, ...) is missing."""


def _fmt_value(v: Any) -> str:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}" if v == 0 or 1e-3 <= abs(v) < 1e4 else f"{v:.3e}"


_SUMMARY_KEYS = (("e1_rms", "m"), ("e1_max", "m"), ("e2_rms", "m"), ("e2_max", "m"),
                 ("e2_plant_rms", "m"), ("e2_plant_max", "m"), ("beta_min", ""), ("mujoco_warnings", ""))


def _print_summary(scn, traj, metrics: dict | None, out: Path | None, written: list[Path]) -> None:
    n = len(traj)
    t_end = float(traj.t[-1]) if n else 0.0
    plant = scn.plant.kind
    if plant == "mujoco":
        plant += f", {scn.plant.segments} segments/section, {scn.plant.actuation}"
    print(f"run '{scn.name}': status {traj.status} - {n} of {scn.n_steps} steps, t = {t_end:.3f} s "
          f"(plant {plant})")
    if traj.message:
        print(f"  message: {_one_line(traj.message)}")
    if metrics:
        items = [f"{k} = {_fmt_value(metrics[k])}{' ' + u if u else ''}"
                 for k, u in _SUMMARY_KEYS if jsonable(metrics.get(k)) is not None]  # skip None/NaN
        for i in range(0, len(items), 3):
            print("  " + "   ".join(items[i:i + 3]))
    if out is not None:
        names = ", ".join(p.name if p.parent == out else str(p) for p in written)
        print(f"  outputs in {out}/: {names or '(none)'}")


def _simulate_and_write(scn, out: Path | None, progress: bool, live=None, record_rate: float | None = None):
    """Simulate, compute metrics and (if out) write every output (`harness.api.run_scenario`), then print
    the summary.  live: optional harness.output.viewer.LiveView that receives the run chunk by chunk
    while it is simulated.  Returns (traj, metrics or None, output-writing failures, interrupted flag)."""
    api = _import("harness.api")
    res = api.run_scenario(scn, out, progress, handle_signals=True, record_rate=record_rate,
                           on_chunk=live.on_chunk if live is not None else None)
    if live is not None:
        live.finish(res.traj)
    _print_summary(scn, res.traj, res.metrics, out, res.written)
    for f in res.failures:
        _warn(f"could not produce {f}")
    return res.traj, res.metrics, res.failures, res.interrupted


def _run_exit_code(traj, failures: list[str], interrupted: bool, wrote: bool = True) -> int:
    if interrupted:
        t_end = float(traj.t[-1]) if len(traj) else 0.0
        note = "; outputs written for the completed part" if wrote else ""
        _err(f"run interrupted at t = {t_end:.3f} s{note}")
        return EXIT_INTERRUPTED
    if traj.status != "ok":
        _err(f"run {traj.status}: {traj.message or 'no message'}")
        return EXIT_FAIL
    if failures:
        _err(f"{len(failures)} output(s) could not be produced (see warnings above)")
        return EXIT_FAIL
    return EXIT_OK


# ---------------------------------------------------------------------------------------------
# commands
# ---------------------------------------------------------------------------------------------
def cmd_run(args: argparse.Namespace) -> int:
    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / scn.name)
    live = _import("harness.output.viewer").LiveView.open(args.view, scn) if args.view else None
    if live is not None and live.url:
        print(f"web viewer: {live.url}", file=sys.stderr)
    traj, _, failures, interrupted = _simulate_and_write(scn, out, progress=not args.no_progress, live=live,
                                                         record_rate=args.record_rate)
    rc = _run_exit_code(traj, failures, interrupted)
    if live is not None:
        if live.failed:
            _warn(f"live view: {live.failed}")
        if live.url and not interrupted:
            print(f"serving the web viewer at {live.url} - Ctrl-C to stop", file=sys.stderr)
            with contextlib.suppress(KeyboardInterrupt):
                while not threading.Event().wait(0.5):  # short waits: Ctrl-C is handled promptly
                    pass
        live.close()
    return rc


def cmd_check(args: argparse.Namespace) -> int:
    from harness.config.bounds import check_bounds, load_bounds

    scn = load_from_args(args)
    bounds = load_bounds(args.bounds)
    out = prepare_out_dir(args.out) if args.out is not None else None
    traj, metrics, failures, interrupted = _simulate_and_write(scn, out, progress=not args.no_progress,
                                                               record_rate=args.record_rate)
    if interrupted:
        return _run_exit_code(traj, failures, interrupted, wrote=out is not None)
    if metrics is None:
        _err(f"no metrics could be computed, bounds not checked ({failures[0] if failures else 'unknown'})")
        return EXIT_FAIL
    violations = check_bounds(metrics, bounds)
    if violations:
        print(f"check against {args.bounds}: {len(violations)} bound(s) violated")
        for v in violations:
            print(f"  FAIL {v}")
        return EXIT_FAIL
    print(f"check against {args.bounds}: all bounds satisfied")
    if out is not None and failures:
        _err(f"{len(failures)} output(s) could not be produced (see warnings above)")
        return EXIT_FAIL
    return EXIT_OK


def cmd_models(args: argparse.Namespace) -> int:
    extra = []
    if args.enforce_cc is not None:
        flag = "true" if args.enforce_cc else "false"
        extra.append((f"plant.enforce_cc={flag}", "--enforce-cc" if args.enforce_cc else "--no-enforce-cc"))
    scn = load_from_args(args, extra)
    p = scn.plant
    path = args.out if args.out is not None else Path(
        "mjcf") / f"octarm_{p.actuation}_n{p.segments}{'_cc' if p.enforce_cc else ''}.xml"
    if path.is_dir():
        raise ConfigError(f"--out = '{path}': is a directory, expected a file name", path="--out")
    prepare_out_dir(path.parent if str(path.parent) else Path("."))
    plant_model = _import("harness.plant.mujoco_model")
    result = plant_model.export_mjcf(scn.plant_master, scn.plant_slave, p, path)
    print(f"wrote {result if isinstance(result, (str, Path)) else path} "
          f"({p.segments} segments/section, {p.actuation} actuation, enforce_cc={str(p.enforce_cc).lower()})")
    return EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    from harness.config.assets import shipped

    study: Path = shipped(args.study, "studies")
    if not study.is_file():
        raise ConfigError(f"study file not found: {study}", path=str(study))
    if args.view is not None:
        return _view_case(study, args.out, args.view)
    sweep = _import("harness.studies.sweep")  # validates the study, then creates and checks the output folder
    extra = {"max_cases": args.max_cases} if args.max_cases is not None else {}
    rc = sweep.main_sweep(study, args.out, args.workers, args.scheduler, not args.no_progress, **extra)
    return int(rc) if isinstance(rc, int) and not isinstance(rc, bool) else EXIT_OK


def cmd_controllers(args: argparse.Namespace) -> int:  # noqa: ARG001
    registry = _import("harness.loop.controllers")
    items = registry.describe_builtins()
    width = max(len(n) for n, _, _ in items)
    for name, desc, acts in items:
        print(f"{name:<{width}}  [{'/'.join(acts):<12}]  {desc}")
    print("your own: --controller path/to/file.py:ClassName or package.module:ClassName "
          "(see controllers/interface.py)")
    return EXIT_OK


def _view_case(study: Path, out: Path | None, case_id: str) -> int:
    """`teleop sweep STUDY --view CASE_ID`: open a case's recording in a spawned Rerun viewer."""
    import subprocess

    if out is None:
        out = Path("runs") / "sweeps" / _import("harness.studies.sweep").load_study(study).name
    path = out / "recordings" / f"{case_id}.rrd"
    if not path.is_file():
        have = sorted(p.stem for p in (out / "recordings").glob("*.rrd"))
        raise ConfigError(f"--view {case_id}: no recording {path} (recorded cases: "
                          f"{', '.join(have) or 'none'}; re-run the case with 'teleop run --view')",
                          path="--view")
    cmd = _import("harness.output.viewer").open_recording(path)
    subprocess.Popen(cmd, start_new_session=True, stdin=subprocess.DEVNULL)
    print(f"opened {path} ({' '.join(cmd)})")
    return EXIT_OK


def parse_segment_list(text: str) -> list[int]:
    """'4,8,16,32' -> [4, 8, 16, 32]; each an integer in [1, 64], no duplicates."""
    items = [s.strip() for s in str(text).split(",")]
    out: list[int] = []
    for s in items:
        try:
            v = int(s)
        except ValueError:
            v = None
        if v is None or not 1 <= v <= 64 or v in out:
            raise ConfigError(f"--segments = {text!r}: must be distinct integers in [1, 64] separated by "
                              f"commas, e.g. 4,8,16,32 (bad entry {s!r})", path="--segments")
        out.append(v)
    return out


def cmd_fidelity(args: argparse.Namespace) -> int:
    segments = parse_segment_list(args.segments)
    out = prepare_out_dir(args.out)
    if args.reference == "cosserat":
        report = _import("harness.studies.fidelity_report")
        rc = report.main_reference(segments, out, not args.no_progress, args.seed)
    else:
        fidelity = _import("harness.studies.fidelity")
        rc = fidelity.main_fidelity(segments, out, not args.no_progress, args.samples, args.seed)
    return int(rc) if isinstance(rc, int) and not isinstance(rc, bool) else EXIT_OK


# ---------------------------------------------------------------------------------------------
def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help / --version (0) or a usage error (2, already printed)
        return e.code if isinstance(e.code, int) else (EXIT_OK if e.code is None else EXIT_USAGE)
    if not getattr(args, "command", None):
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    try:
        return args.func(args)
    except KeyboardInterrupt:
        _err("interrupted")
        return EXIT_INTERRUPTED
    except _Unavailable as e:
        _err(e)
        return EXIT_FAIL
    except OSError as e:  # a file that could not be read or written (bad path, full disk): one line
        where = f"{e.filename}: " if e.filename else ""
        _err(f"{where}{e.strerror or e}")
        return EXIT_USAGE
    except Exception as e:
        if isinstance(e, _user_error_types()):
            _err(e)
            return EXIT_USAGE
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
