"""The `teleop` argument parser: every command, option, default and help text (`teleop --help`).
`harness.cli` maps the parsed command to its function."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
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


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0.0 < v < math.inf:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def _port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = -1
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number in [0, 65535], got {text!r}")
    return v


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
                   help="Slave actuation (MuJoCo chain and Cosserat rod), each defined per unit length of a "
                        "section: 'servo' "
                        "(position servos tracking the integrated command; hides the slave's inertia and the "
                        "controller's dynamics model), 'torque' (the controller's T2 as ideal generalized "
                        "forces; hides actuator dynamics and limits) or 'muscle' (two one-sided extensor "
                        "groups per section, force lag tau and limit F_max: pushes only, clips commands "
                        "outside [0, F_max], lags by tau; plant.muscle_* fields). "
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
        p.add_argument("--allow-code", action="store_true",
                       help="let the scenario file (or a replayed config.toml) name a Python controller "
                            "('file.py:Class', 'package.module:Class') and run it; only for files you trust. "
                            "A controller given with --controller needs no such option. Default: such a file "
                            "is refused.")
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
                        "Default: 100 (chosen by measurement, see the docs' Performance page).")


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
    parser.add_argument("--version", action=_VersionAction, help="print the package version and exit.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")

    run = sub.add_parser(
        "run", formatter_class=_Formatter, help="simulate one scenario and write its outputs",
        description="Load and validate a scenario, simulate it and write into the output folder: "
                    "config.toml (fully resolved scenario, written before simulating), metrics.json, "
                    "run.rrd (Rerun recording) and the PNG figures. Outputs are written even when the run "
                    "diverges or is interrupted (Ctrl-C / SIGTERM stop the run cleanly; a second Ctrl-C "
                    "aborts).",
        epilog="exit status: 0 ok; 1 diverged / outputs not written / the --view viewer could not be opened "
               "(then nothing ran); 2 invalid input; 130 interrupted.")
    _add_scenario_options(run)
    _add_out_and_progress(run, "output folder (created; must be writable). Default: runs/<scenario name>.")
    run.add_argument("--view", nargs="?", const="native", choices=("native", "web"), default=None,
                     help="stream the run to a Rerun viewer while it is simulated: 'native' (the default "
                          "with a bare --view) spawns the viewer, 'web' serves Rerun's web viewer and waits "
                          "for Ctrl-C after the run. run.rrd is written as without it. Without a display, "
                          "'native' stops before running with a line naming --view web. Default: no viewer.")
    run.add_argument("--view-host", metavar="HOST", default="127.0.0.1",
                     help="address the web viewer (--view web) listens on. Anything but a loopback address "
                          "serves the run to other machines, without authentication (a warning is printed). "
                          "Default: 127.0.0.1.")
    run.add_argument("--web-port", metavar="N", type=_port, default=9090,
                     help="HTTP port of the web viewer (--view web), 0 for any free port. Default: 9090.")
    run.add_argument("--grpc-port", metavar="N", type=_port, default=9876,
                     help="port the web viewer reads the run's data from (--view web), 0 for any free port. "
                          "Default: 9876.")
    _add_record_rate(run)

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

    sweep = sub.add_parser(
        "sweep", formatter_class=_Formatter, help="run a parameter sweep (study file)",
        description="Run every case of a study file (harness.studies.sweep) in local worker processes or "
                    "on a Dask cluster. Each finished case is appended to results.jsonl as it finishes; "
                    "re-running the same command resumes (finished cases are skipped). Also written: "
                    "summary.csv, metric plots (lines for 1-D factors, heatmaps for 2-D grids), "
                    "study.toml (resolved) and optional recordings of the worst cases.",
        epilog="study file (TOML; see studies/*.toml and the docs' study file reference): [study] name, "
               "scenario (base "
               "scenario file), set (overrides for every case), metrics, record = {worst = k, by = METRIC}; "
               "[[factor]] param = any scenario key (e.g. plant.slave.masses[0]) with scale = [...] "
               "(x nominal), values = [...] or scale/values = {random = 'uniform', low, high}; "
               "[sampling] mode = 'grid' | 'random', n, seed. "
               "exit status: 0 every case has a row (diverged cases are rows too); 1 cases unfinished, "
               "the executor failed, or an output (recordings, summary) could not be written after the "
               "cases ran (the rest, summary.csv included, is written); 2 invalid study, option or output "
               "folder; 130 interrupted (re-run to resume).")
    sweep.add_argument("study", metavar="STUDY.toml", type=_path, help="study file describing the sweep.")
    sweep.add_argument("--out", metavar="DIR", type=_path, default=None,
                       help="output folder (created; must be writable; an existing sweep folder is "
                            "resumed). Default: runs/sweeps/<study name>.")
    sweep.add_argument("--workers", metavar="N", type=_positive_int, default=None,
                       help="number of cases run at once (worker processes or threads), integer >= 1 "
                            "(ignored with --scheduler). "
                            f"Default: all cores ({os.cpu_count() or 1} here).")
    sweep.add_argument("--executor", choices=("processes", "threads"), default="processes",
                       help="what runs the cases: 'processes' (worker processes; a crashing case takes only "
                            "its worker) or 'threads' (threads of this process, no worker processes: the "
                            "compiled loops release the GIL; Python-stepped plants and controllers then run "
                            "one at a time). Results are the same. Not with --scheduler. "
                            "Default: processes.")
    sweep.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="address of a running Dask scheduler (e.g. tcp://host:8786) to run on a "
                            "cluster. Default: none (local processes).")
    sweep.add_argument("--max-cases", metavar="N", type=_positive_int, default=None,
                       help="refuse a study with more than N cases, checked before the cases are built "
                            "(replaces the study's [sampling] max_cases). "
                            "Default: from the study, else 10000.")
    sweep.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                       help="override a field of the study's base scenario for every case, after the "
                            "study's own set (dotted key and TOML value, as 'teleop run --set', e.g. "
                            "--set duration=2); repeatable. A factor on the same key wins. Part of the "
                            "resolved study.toml and of the case ids. Default: none.")
    sweep.add_argument("--case-timeout", metavar="SECONDS", type=_positive_float, default=None,
                       help="wall-time limit per case, set-up included (a cold kernel cache adds 20-60 s "
                            "to the first cases of a machine): a case over it becomes a row with status "
                            "'error' and the other cases run. The case is stopped at its next chunk of "
                            "steps; on worker processes, one that blocks is stopped 10 s later. "
                            "Default: no limit.")
    sweep.add_argument("--no-progress", action="store_true",
                       help="do not show the progress bar (default: shown on stderr when it is a "
                            "terminal).")
    sweep.add_argument("--allow-code", action="store_true",
                       help="let the study (its scenario, set or controller factor) name Python controllers "
                            "('file.py:Class', 'package.module:Class', paths relative to the study file) and "
                            "run them; only for studies you trust. Default: such a study is refused.")
    sweep.add_argument("--view", metavar="CASE_ID", default=None,
                       help="do not run: open the recording of case CASE_ID of this sweep "
                            "(<out>/recordings/CASE_ID.rrd, written for the worst cases, see record) in a "
                            "Rerun viewer. Default: run the sweep.")

    sub.add_parser(
        "controllers", formatter_class=_Formatter, help="list the built-in controllers",
        description="List the built-in controllers (name, supported plant actuations, one-line description). "
                    "Your own: --controller path/to/file.py:ClassName (docs: guide, Controllers).",
        epilog="Default controller of every scenario: paper (the paper's laws on the compiled fast path).")

    cache = sub.add_parser(
        "cache", formatter_class=_Formatter, help="list or prune the compiled-kernel cache",
        description="List the folders of the compiled-kernel cache ($TELEOP_CACHE_DIR, else "
                    "$XDG_CACHE_HOME/octarm-teleop, else ~/.cache/octarm-teleop) with their sizes, marking "
                    "those this installation uses on this machine. Every change of the kernel sources or of "
                    "numba/numpy/Python starts new folders; the old ones are never read again. "
                    "Default: list only.",
        epilog="Removing a folder another installation (or another machine sharing the folder) still uses "
               "costs that one a single recompilation, 20-60 s, at its next run.")
    what = cache.add_mutually_exclusive_group()
    what.add_argument("--prune", action="store_true",
                      help="remove the folders this installation does not use (other code versions). "
                           "Default: keep them.")
    what.add_argument("--clear", action="store_true",
                      help="remove every cache folder (the next run compiles again, 20-60 s). "
                           "Default: keep them.")

    smap = sub.add_parser(
        "stability-map", formatter_class=_Formatter, help="survival map over null-space gain x rod damping",
        description="Run the paper scenario over a grid of the null-space gain k_n (eq. 27-28) and the "
                    "bending viscosity eta_b, for the free chain and the CC chain, servo and torque "
                    "(harness.studies.stability_map): the time each cell survives and its e2_rms. Writes "
                    "stability_map.md and stability_map.png.")
    smap.add_argument("--duration", metavar="S", type=_positive_float, default=3.0,
                      help="simulated seconds per cell, > 0. Default: 3.")
    smap.add_argument("--out", metavar="DIR", type=_path, default=Path("runs/stability_map"),
                      help="output folder (created; must be writable). Default: runs/stability_map.")

    stab = sub.add_parser(
        "stability", formatter_class=_Formatter, help="linear stability of the closed loop at a time point",
        description="Run the scenario (paper law, sensing without noise) to time --at and linearize the "
                    "sampled-data closed loop over one control period (plant state, servo reference, "
                    "actuation-delay ring; zero-order hold) by central finite differences of the one-period "
                    "map (harness.studies.stability). Prints the verdict (stable / marginal: slower than "
                    "e-fold per second / unstable), the spectral radius and the least stable modes with "
                    "their frequency and dominant joints or sections; writes spectrum.csv, stability.json "
                    "and stability.png (spectrum and mode shapes on the arm).",
        epilog="exit status: 0 stable or marginal; 1 unstable, or the run stopped before --at; "
               "2 invalid input.")
    _add_scenario_options(stab)
    stab.add_argument("--at", metavar="T[,T...]|START:STOP:STEP", type=_times, default=(1.0,),
                      help="time(s) of the point(s) of linearization in s, each in [0, 3600]: one time, a "
                           "comma-separated list or START:STOP:STEP (both ends included), all on one run; "
                           "with several, one line per time and the outputs of the least stable. Default: 1.")
    stab.add_argument("--fd-step", metavar="H", type=_positive_float, default=None,
                      help="relative central-difference step, in (0, 0.01). Default: 1e-6 analytic, "
                           "1e-7 MuJoCo and rod.")
    stab.add_argument("--modes", metavar="N", type=_positive_int, default=6,
                      help="least stable modes printed, integer >= 1. Default: 6.")
    stab.add_argument("--out", metavar="DIR", type=_path, default=None,
                      help="output folder (created; must be writable). "
                           "Default: runs/stability/<scenario name>.")

    mar = sub.add_parser(
        "margin", formatter_class=_Formatter, help="robustness margins of a scenario against a bounds file",
        description="For each mismatch parameter, the largest deviation from the scenario in each "
                    "direction for which it still passes the bounds file: the pass/fail edge bracketed (x2 "
                    "steps) and bisected to --rtol, plus --probes points inside each margin to detect a "
                    "non-monotone edge (harness.studies.margin). Runs go through the sweep executor; each "
                    "finished run is appended to OUT/results.jsonl and a re-run resumes. Writes margins.md "
                    "(table: parameter, lower and upper margin, first bound to fail, metric at the edge), "
                    "margins.json, margins.png (bars around the nominal point) and, with --pair, edge.json / "
                    "edge.png. A margin on a servo plant over a dynamics parameter (masses) measures little: "
                    "the servos hide the slave's inertia.",
        epilog="parameters: slave_mass, bending_stiffness, extension_stiffness, master_mass (scale factors "
               "in [0.05, 20]), material_damping (scale of plant.bending_viscosity and extension_viscosity, "
               "[0.01, 100]; chain and rod), control_rate (scale, [0.1, 10]), segments (1-64, chain), delay "
               "(s, [0, 0.1], multiples of control_dt; chain and rod), noise_snr (dB, [0, 200]), or any "
               "dotted scenario key as a scale factor. exit status: 0 margins found; 1 the executor "
               "failed; 2 invalid input or the nominal scenario fails the bounds; 130 interrupted (re-run "
               "to resume).")
    _add_scenario_options(mar)
    mar.add_argument("--bounds", metavar="BOUNDS.toml", type=_path, required=True,
                     help="bounds file (required; layout: bounds/paper_mujoco.toml).")
    mar.add_argument("--param", dest="params", action="append", default=None, metavar="NAME",
                     help="parameter to search (repeatable). Default: slave_mass, bending_stiffness, "
                          "extension_stiffness, material_damping, segments, control_rate, delay, noise_snr, "
                          "master_mass (those that do not apply to the plant are listed as n/a).")
    mar.add_argument("--rtol", metavar="R", type=_positive_float, default=0.05,
                     help="relative tolerance of a scale-factor edge (fail / pass - 1), in (0, 1). "
                          "Default: 0.05.")
    mar.add_argument("--probes", metavar="N", type=_nonnegative_int, default=2,
                     help="points per side run inside the margin to detect a non-monotone edge, integer in "
                          "[0, 10]. Default: 2.")
    mar.add_argument("--pair", metavar="P1,P2", default=None,
                     help="also trace the pass/fail edge of two scale parameters in their plane (8 rays). "
                          "Default: none.")
    mar.add_argument("--workers", metavar="N", type=_positive_int, default=None,
                     help=f"runs at once, integer >= 1. Default: all cores ({os.cpu_count() or 1} here).")
    mar.add_argument("--executor", choices=("processes", "threads"), default="processes",
                     help="what runs the cases (as 'teleop sweep'). Default: processes.")
    mar.add_argument("--scheduler", metavar="ADDRESS", default=None,
                     help="address of a running Dask scheduler. Default: none (local).")
    mar.add_argument("--out", metavar="DIR", type=_path, default=None,
                     help="output folder (created; must be writable; an existing one is resumed). "
                          "Default: runs/margin/<scenario name>.")
    mar.add_argument("--no-progress", action="store_true",
                     help="do not print each round (default: printed on stderr).")

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
    fnd = sub.add_parser(
        "findings", formatter_class=_Formatter, help="rerun the findings and check their claims",
        description="Rerun the shipped findings (findings/*.toml: runs of a scenario plus the claim as "
                    "bounds; harness.studies.findings), print claim / measured / holds for each, and write "
                    "the markdown table the docs' findings page includes and the figures of the runs a "
                    "finding names.")
    fnd.add_argument("names", nargs="*", metavar="NAME",
                     help="finding names (shipped: see findings/) or finding files. Default: all shipped.")
    fnd.add_argument("--table", metavar="FILE", type=_path, default=None,
                     help="markdown table of all findings, written when all of them run (and one table per "
                          "finding, FILE's stem + '-NAME.md', always; parent folders created). Default: "
                          "docs/findings-table.md in a checkout (a folder with mkdocs.yml, whose findings "
                          "page includes it), else runs/findings/findings-table.md.")
    fnd.add_argument("--figures", metavar="DIR", type=_path, default=None,
                     help="folder for the figures of the runs a finding names. Default: docs/figures in a "
                          "checkout, else runs/findings/figures.")
    fnd.add_argument("--no-write", action="store_true",
                     help="print only; write neither the table nor the figures. Default: write them.")
    fnd.add_argument("--list", action="store_true",
                     help="list the shipped findings and exit. Default: run them.")
    return parser


class _VersionAction(argparse.Action):
    """argparse's "version" action, with the version looked up only when asked for (reading the
    installed package's metadata costs ~40 ms, which every command paid when the parser was built)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        parser._print_message(f"{parser.prog} {_version()}\n", sys.stdout)
        parser.exit()


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("octarm-teleop")
    except Exception:  # noqa: BLE001 - not installed: version unknown
        return "unknown"
