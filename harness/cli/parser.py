"""The `teleop` argument parser: every command, option, default and help text (`teleop --help`)."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import NoReturn

from harness.config.scenario import ACTUATIONS, PLANTS

EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def one_line(text) -> str:
    """Any message as one line (whitespace runs collapsed)."""
    return " ".join(str(text).split()) or "(no message)"


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one `error: ...` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"error: {self.prog}: {one_line(message)} (see '{self.prog} --help')\n")


class _Formatter(argparse.HelpFormatter):
    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=32, width=100)


def _typed(convert, ok, expected: str):
    """argparse type: `convert(text)` if it succeeds and `ok(value)`, else 'expected <expected>'."""
    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            v = None
        if v is None or not ok(v):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return v

    return parse


_positive_int = _typed(int, lambda v: v >= 1, "an integer >= 1")
_nonnegative_int = _typed(int, lambda v: v >= 0, "an integer >= 0")
_positive_float = _typed(float, lambda v: 0.0 < v < math.inf, "a positive number")
_port = _typed(int, lambda v: 0 <= v <= 65535, "a port number in [0, 65535]")
_record_rate = _typed(lambda s: math.inf if s.strip().lower() == "full" else float(s), lambda v: v > 0,
                      "a rate in Hz > 0 or 'full'")
_rtol = _typed(float, lambda v: 0.0 < v < 1.0, "a relative tolerance in (0, 1)")
_probes = _typed(int, lambda v: 0 <= v <= 10, "an integer in [0, 10]")
_path = _typed(lambda s: Path(s) if s.strip() else None, bool, "a path, not an empty string")


def _segment_list(text: str) -> list[int]:
    """argparse type of `fidelity --segments`: '4,8,16,32' -> [4, 8, 16, 32], distinct integers in [1, 64]."""
    out: list[int] = []
    for s in (s.strip() for s in str(text).split(",")):
        if not s.isdigit() or not 1 <= int(s) <= 64 or int(s) in out:
            raise argparse.ArgumentTypeError(f"must be distinct integers in [1, 64] separated by commas, "
                                             f"e.g. 4,8,16,32 (bad entry {s!r})")
        out.append(int(s))
    return out


def _times(text: str) -> tuple[float, ...]:
    """argparse type of `stability --at`: 'T', 'T1,T2,...' or 'START:STOP:STEP' (s), increasing."""
    try:
        if ":" in text:
            a, b, c = (float(x) for x in text.split(":"))
            if not c > 0:
                raise ValueError
            n = int(math.floor((b - a) / c + 1e-9))
            ts = tuple(round(a + i * c, 12) for i in range(n + 1))
        else:
            ts = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected T, T1,T2,... or START:STOP:STEP in s, got {text!r}") from None
    if not ts or any(not (0.0 <= t <= 3600.0) for t in ts) or list(ts) != sorted(set(ts)):
        raise argparse.ArgumentTypeError(f"expected increasing times in [0, 3600] s, got {text!r}")
    return ts


def _scenario_options(p: argparse.ArgumentParser, *, sim: bool = True) -> None:
    a = p.add_argument
    a("scenario", nargs="?", metavar="SCENARIO.toml", default=None,
      help="scenario file (layout: scenarios/paper.toml). Default: the built-in paper scenario (the values "
           "scenarios/paper.toml spells out).")
    if sim:
        a("--plant", choices=PLANTS, default=None,
          help="simulated plant: 'mujoco' (MuJoCo multibody model), 'analytic' (RK4 on the analytic model) "
               "or 'cosserat' (PyElastica Cosserat rod); --set plant.kind=... Default: from the scenario "
               "(paper: mujoco).")
    a("--actuation", choices=ACTUATIONS, default=None,
      help="slave actuation (MuJoCo chain and Cosserat rod), per unit section length: 'servo' (position "
           "servos on the integrated command; hide the slave's inertia and the controller's dynamics model), "
           "'torque' (T2 as ideal generalized forces; hides actuator dynamics and limits) or 'muscle' (two "
           "one-sided extensor groups per section: push only, clip to [0, F_max], lag tau; plant.muscle_*); "
           "--set plant.actuation=... Default: from the scenario (paper: servo).")
    a("--segments", metavar="N", default=None,
      help="rigid segments per slave section of the MuJoCo model, integer in [1, 64]; --set "
           "plant.segments=N. Default: from the scenario (paper: 8).")
    if sim:
        a("--duration", metavar="S", default=None,
          help="simulated time in s, in (0, 3600]; must exceed the metrics' 'transient' (paper: 5 s; unset: "
               "duration / 4 for runs of 5 s or less). Default: from the scenario (paper: 20).")
        a("--controller", metavar="NAME|FILE.py:CLASS", default=None,
          help="a built-in controller ('teleop controllers'; 'paper' = the paper's law, compiled), "
               "'path/to/file.py:ClassName' or 'package.module:ClassName' (controllers/interface.py); --set "
               "controller.name=...; parameters: --set controller.params.KEY=VALUE. Default: from the "
               "scenario (paper: paper).")
        a("--allow-code", action="store_true",
          help="let the scenario file (or a replayed config.toml) name a Python controller and run it; only "
               "for files you trust (--controller needs no such option). Default: such a file is refused.")
        a("--seed", metavar="N", default=None,
          help="noise seed, integer >= 0. Default: from the scenario (paper: 0).")
        a("--snr", metavar="DB|none", default=None,
          help="signal-to-noise ratio in dB of the AWGN on the fed-back states, in [0, 200], or 'none'. "
               "Default: from the scenario (paper: 40).")
    a("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
      help="override a scenario field by its dotted key with a TOML value (e.g. plant.segments=16, "
           "plant.slave.masses=[1.2,0.7,0.4], snr_db=30). Repeatable; applied in order after the shortcut "
           "options.")


def _out(p: argparse.ArgumentParser, default: Path | None, help: str, metavar: str = "DIR") -> None:
    p.add_argument("--out", metavar=metavar, type=_path, default=default, help=help)


def _no_progress(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-progress", action="store_true",
                   help="do not show progress (default: shown on stderr when it is a terminal).")


def _record_rate_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--record-rate", metavar="HZ|full", type=_record_rate, default=None,
                   help="rate of the 3-D geometry (arms, segments, backbone) in run.rrd, Hz > 0, or 'full' "
                        "for every control step; time series are always at the control rate. Default: 100 "
                        "(measured, see the docs' Performance page).")


def _pool_options(p: argparse.ArgumentParser) -> None:
    a = p.add_argument
    a("--workers", metavar="N", type=_positive_int, default=None,
      help="cases run at once (worker processes or threads), integer >= 1 (ignored with --scheduler). "
           f"Default: all cores ({os.cpu_count() or 1} here).")
    a("--executor", choices=("processes", "threads"), default="processes",
      help="what runs the cases: 'processes' (a crashing case takes only its worker) or 'threads' (no worker "
           "processes: the compiled loops release the GIL; Python-stepped plants and controllers run one at "
           "a time). Same results. Not with --scheduler. Default: processes.")
    a("--scheduler", metavar="ADDRESS", default=None,
      help="address of a running Dask scheduler (e.g. tcp://host:8786). Default: none (local).")


_STATUS = "exit status: 0 ok; 1 {one}; 2 invalid input; 130 interrupted."
_BOUNDS_HELP = "bounds file (required; layout: bounds/paper_mujoco.toml)."


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="teleop", formatter_class=_Formatter,
        description="Validation harness for teleoperating a continuum arm (Octarm) with a 2-link rigid "
                    "master.",
        epilog="exit status: 0 ok; 1 run failed (diverged, outputs not written) or bounds violated; 2 "
               "invalid input; 130 interrupted (SIGINT/SIGTERM). Set TELEOP_DEBUG=1 to print tracebacks of "
               "output-writing failures. Run 'teleop COMMAND --help' for the options of each command.")
    parser.add_argument("--version", action=_VersionAction, help="print the package version and exit.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")

    def command(name: str, help: str, description: str, epilog: str | None = None) -> argparse.ArgumentParser:
        return sub.add_parser(name, formatter_class=_Formatter, help=help, description=description,
                              epilog=epilog)

    run = command(
        "run", "simulate one scenario and write its outputs",
        "Load and validate a scenario, simulate it and write into the output folder: config.toml (the "
        "resolved scenario, written before simulating), metrics.json, run.rrd (Rerun recording) and the PNG "
        "figures. Outputs are written even when the run diverges or is interrupted (Ctrl-C / SIGTERM stop "
        "the run cleanly; a second Ctrl-C aborts).",
        _STATUS.format(one="diverged / outputs not written / the --view viewer could not be opened (then "
                           "nothing ran)"))
    _scenario_options(run)
    _out(run, None, "output folder (created; must be writable). Default: runs/<scenario name>.")
    _no_progress(run)
    run.add_argument("--view", nargs="?", const="native", choices=("native", "web"), default=None,
                     help="stream the run to a Rerun viewer while it is simulated: 'native' (a bare --view) "
                          "spawns the viewer, 'web' serves Rerun's web viewer and waits for Ctrl-C after the "
                          "run. run.rrd is written as without it. Without a display, 'native' stops before "
                          "running with a line naming --view web. Default: no viewer.")
    run.add_argument("--view-host", metavar="HOST", default="127.0.0.1",
                     help="address the web viewer (--view web) listens on; any but a loopback address serves "
                          "the run to other machines, without authentication (a warning is printed). "
                          "Default: 127.0.0.1.")
    run.add_argument("--web-port", metavar="N", type=_port, default=9090,
                     help="HTTP port of the web viewer (--view web), 0 for any free port. Default: 9090.")
    run.add_argument("--grpc-port", metavar="N", type=_port, default=9876,
                     help="port the web viewer reads the run's data from (--view web), 0 for any free port. "
                          "Default: 9876.")
    _record_rate_option(run)

    check = command(
        "check", "simulate a scenario and check acceptance bounds",
        "Like 'run', then compare the metrics with a bounds file and list every violated bound with its "
        "measured value and limit. Outputs are written only with --out.",
        "exit status: 0 all bounds satisfied; 1 a bound is violated (or the run failed); 2 invalid input; "
        "130 interrupted.")
    _scenario_options(check)
    check.add_argument("--bounds", metavar="BOUNDS.toml", type=_path, required=True, help=_BOUNDS_HELP)
    _out(check, None, "also write the run outputs (as 'run' does) into this folder. Default: no files.")
    _no_progress(check)
    _record_rate_option(check)

    models = command(
        "models", "export the generated MuJoCo model (MJCF)",
        "Write the MJCF of the scenario's plant master and plant slave (with any [plant.master] / "
        "[plant.slave] mismatch), harness.plant.mujoco_model.export_mjcf.")
    _scenario_options(models, sim=False)
    models.add_argument("--enforce-cc", action=argparse.BooleanOptionalAction, default=None,
                        help="with / without the equality constraints holding each section at constant "
                             "curvature (plant.enforce_cc). Default: from the scenario (paper: false).")
    _out(models, None, "output MJCF file (parent folders are created). Default: "
                       "mjcf/octarm_<actuation>_n<segments>[_cc].xml.", "FILE.xml")

    sweep = command(
        "sweep", "run a parameter sweep (study file)",
        "Run every case of a study file in local workers or on a Dask cluster; each finished case is "
        "appended to results.jsonl and a re-run resumes. Also written: summary.csv, metric plots, study.toml "
        "(resolved) and optional recordings of the worst cases.",
        "study file: see studies/*.toml and the docs' study file reference. exit status: 0 every case has a "
        "row (diverged cases too); 1 cases unfinished, the executor failed, or an output could not be "
        "written after the cases ran; 2 invalid study, option or output folder; 130 interrupted (re-run to "
        "resume).")
    sweep.add_argument("study", metavar="STUDY.toml", type=_path, help="study file describing the sweep.")
    _out(sweep, None, "output folder (created; must be writable; an existing sweep folder is resumed). "
                      "Default: runs/sweeps/<study name>.")
    _pool_options(sweep)
    sweep.add_argument("--max-cases", metavar="N", type=_positive_int, default=None,
                       help="refuse a study with more than N cases, checked before the cases are built "
                            "(replaces the study's [sampling] max_cases). Default: from the study, "
                            "else 10000.")
    sweep.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                       help="override a field of the study's base scenario for every case, after the study's "
                            "own set (as 'teleop run --set', e.g. --set duration=2); repeatable. A factor on "
                            "the same key wins. Part of the resolved study.toml and of the case ids. "
                            "Default: none.")
    sweep.add_argument("--case-timeout", metavar="SECONDS", type=_positive_float, default=None,
                       help="wall-time limit per case, set-up included (a cold kernel cache adds 20-60 s to "
                            "the first cases of a machine): a case over it becomes a row with status 'error' "
                            "and the others run. It is stopped at its next chunk of steps; a worker process "
                            "that blocks is stopped 10 s later. Default: no limit.")
    _no_progress(sweep)
    sweep.add_argument("--allow-code", action="store_true",
                       help="let the study (its scenario, set or controller factor) name Python controllers "
                            "(paths relative to the study file) and run them; only for studies you trust. "
                            "Default: such a study is refused.")
    sweep.add_argument("--view", metavar="CASE_ID", default=None,
                       help="do not run: open the recording of case CASE_ID of this sweep "
                            "(<out>/recordings/CASE_ID.rrd, written for the worst cases, see record) in a "
                            "Rerun viewer. Default: run the sweep.")

    command("controllers", "list the built-in controllers",
            "List the built-in controllers (name, supported plant actuations, one-line description). Your "
            "own: --controller path/to/file.py:ClassName (docs: guide, Controllers).",
            "Default controller of every scenario: paper (the paper's laws on the compiled fast path).")

    cache = command(
        "cache", "list or prune the compiled-kernel cache",
        "List the folders of the compiled-kernel cache ($TELEOP_CACHE_DIR, else "
        "$XDG_CACHE_HOME/octarm-teleop, else ~/.cache/octarm-teleop) with their sizes, marking those this "
        "installation uses on this machine. Every change of the kernel sources or of numba/numpy/Python "
        "starts new folders; the old ones are never read again. Default: list only.",
        "Removing a folder another installation (or machine sharing the folder) still uses costs that one a "
        "single recompilation, 20-60 s, at its next run.")
    what = cache.add_mutually_exclusive_group()
    what.add_argument("--prune", action="store_true",
                      help="remove the folders this installation does not use (other code versions). "
                           "Default: keep them.")
    what.add_argument("--clear", action="store_true",
                      help="remove every cache folder (the next run compiles again, 20-60 s). "
                           "Default: keep them.")

    smap = command(
        "stability-map", "survival map over null-space gain x rod damping",
        "Run the paper scenario over a grid of the null-space gain k_n (eq. 27-28) and the bending viscosity "
        "eta_b, for the free and the CC chain, servo and torque (harness.studies.stability_map): the time "
        "each cell survives and its e2_rms. Writes stability_map.md and stability_map.png.")
    smap.add_argument("--duration", metavar="S", type=_positive_float, default=3.0,
                      help="simulated seconds per cell, > 0. Default: 3.")
    _out(smap, Path("runs/stability_map"), "output folder (created; must be writable). "
                                           "Default: runs/stability_map.")

    stab = command(
        "stability", "linear stability of the closed loop at a time point",
        "Run the scenario (paper law, no sensing noise) to time --at and linearize the sampled-data closed "
        "loop over one control period by central finite differences (harness.studies.stability). Prints "
        "the verdict (stable / marginal / unstable), the spectral radius and the least stable modes; writes "
        "spectrum.csv, stability.json and stability.png.",
        "exit status: 0 stable or marginal; 1 unstable, or the run stopped before --at; 2 invalid input.")
    _scenario_options(stab)
    stab.add_argument("--at", metavar="T[,T...]|START:STOP:STEP", type=_times, default=(1.0,),
                      help="time(s) of linearization in s, each in [0, 3600]: one time, a comma-separated "
                           "list or START:STOP:STEP (both ends included), all on one run; with several, one "
                           "line per time and the outputs of the least stable. Default: 1.")
    stab.add_argument("--fd-step", metavar="H", type=_positive_float, default=None,
                      help="relative central-difference step, in (0, 0.01). Default: 1e-6 analytic, 1e-7 "
                           "MuJoCo and rod.")
    stab.add_argument("--modes", metavar="N", type=_positive_int, default=6,
                      help="least stable modes printed, integer >= 1. Default: 6.")
    _out(stab, None, "output folder (created; must be writable). Default: runs/stability/<scenario name>.")

    mar = command(
        "margin", "robustness margins of a scenario against a bounds file",
        "For each mismatch parameter, the largest deviation each way for which the scenario still passes "
        "the bounds: the edge bracketed and bisected to --rtol, --probes points inside to detect a "
        "non-monotone edge (harness.studies.margin). Runs are journaled in OUT/results.jsonl (a re-run "
        "resumes). Writes margins.md, margins.json, margins.png and, with --pair, edge.json / edge.png. On "
        "a servo plant, a dynamics parameter (masses) measures little: the servos hide the inertia.",
        "parameters: slave_mass, bending_stiffness, extension_stiffness, master_mass (scale factors in "
        "[0.05, 20]), material_damping (scale of plant.bending_viscosity and extension_viscosity, "
        "[0.01, 100]; chain and rod), control_rate (scale, [0.1, 10]), segments (1-64, chain), delay (s, "
        "[0, 0.1], multiples of control_dt; chain and rod), noise_snr (dB, [0, 200]), or any dotted scenario "
        "key as a scale factor. exit status: 0 margins found; 1 the executor failed; 2 invalid input or the "
        "nominal scenario fails the bounds; 130 interrupted (re-run to resume).")
    _scenario_options(mar)
    mar.add_argument("--bounds", metavar="BOUNDS.toml", type=_path, required=True, help=_BOUNDS_HELP)
    mar.add_argument("--param", dest="params", action="append", default=None, metavar="NAME",
                     help="parameter to search (repeatable). Default: slave_mass, bending_stiffness, "
                          "extension_stiffness, material_damping, segments, control_rate, delay, noise_snr, "
                          "master_mass (those that do not apply to the plant are listed as n/a).")
    mar.add_argument("--rtol", metavar="R", type=_rtol, default=0.05,
                     help="relative tolerance of a scale-factor edge (fail / pass - 1), in (0, 1). "
                          "Default: 0.05.")
    mar.add_argument("--probes", metavar="N", type=_probes, default=2,
                     help="points per side inside the margin to detect a non-monotone edge, integer in "
                          "[0, 10]. Default: 2.")
    mar.add_argument("--pair", metavar="P1,P2", default=None,
                     help="also trace the pass/fail edge of two scale parameters in their plane (8 rays). "
                          "Default: none.")
    _pool_options(mar)
    _out(mar, None, "output folder (created; must be writable; an existing one is resumed). "
                    "Default: runs/margin/<scenario name>.")
    _no_progress(mar)

    fid = command(
        "fidelity", "plant-fidelity study over MuJoCo segment counts",
        "Compare the MuJoCo chain with N segments per section against the analytic constant-curvature model "
        "(tip, Jacobian, inertia, gravity, elastic forces at random configurations; convergence order) and "
        "with / without the CC constraints (harness.studies.fidelity). Writes fidelity.md, fidelity.csv, "
        "fidelity.png, fidelity_cc.md and fidelity_cc.csv.")
    fid.add_argument("--segments", metavar="N,N,...", type=_segment_list, default="4,8,16,32",
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
    _out(fid, Path("runs/fidelity"), "output folder (created; must be writable). Default: runs/fidelity.")
    _no_progress(fid)

    fnd = command(
        "findings", "rerun the findings and check their claims",
        "Rerun the shipped findings (findings/*.toml: runs of a scenario plus the claim as bounds; "
        "harness.studies.findings), print claim / measured / holds for each, and write the markdown table "
        "the docs' findings page includes and the figures of the runs a finding names.")
    fnd.add_argument("names", nargs="*", metavar="NAME",
                     help="finding names (shipped: see findings/) or finding files. Default: all shipped.")
    fnd.add_argument("--table", metavar="FILE", type=_path, default=None,
                     help="markdown table of all findings, written when all of them run (and one table per "
                          "finding, FILE's stem + '-NAME.md', always; parent folders created). Default: "
                          "docs/findings-table.md in a checkout (a folder with mkdocs.yml), else "
                          "runs/findings/findings-table.md.")
    fnd.add_argument("--figures", metavar="DIR", type=_path, default=None,
                     help="folder for the figures of the runs a finding names. Default: docs/figures in a "
                          "checkout, else runs/findings/figures.")
    fnd.add_argument("--no-write", action="store_true",
                     help="print only; write neither the table nor the figures. Default: write them.")
    fnd.add_argument("--list", action="store_true",
                     help="list the shipped findings and exit. Default: run them.")
    return parser


class _VersionAction(argparse.Action):
    """argparse's "version" action, the version looked up only when asked for (~40 ms)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("octarm-teleop")
        except PackageNotFoundError:
            v = "unknown"
        parser._print_message(f"{parser.prog} {v}\n", sys.stdout)
        parser.exit()
