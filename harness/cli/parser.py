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


class _VersionAction(argparse.Action):
    """argparse's "version" action, the version looked up only when asked for (~40 ms)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from harness.config.runtime import provenance

        parser._print_message(f"{parser.prog} {provenance().get('version', 'unknown')}\n", sys.stdout)
        parser.exit()


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
_positive_float = _typed(float, lambda v: 0.0 < v < math.inf, "a positive number")
_port = _typed(int, lambda v: 0 <= v <= 65535, "a port number in [0, 65535]")
_rtol = _typed(float, lambda v: 0.0 < v < 1.0, "a relative tolerance in (0, 1)")
_probes = _typed(int, lambda v: 0 <= v <= 10, "an integer in [0, 10]")
_nonnegative_int = _typed(int, lambda v: v >= 0, "an integer >= 0")
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


def _o(flag: str, help: str, **kw) -> tuple[str, dict]:
    """An option of the table below: its flag and add_argument keywords."""
    return flag, dict(kw, help=help)


def _out(help: str, default: Path | None = None, metavar: str = "DIR"):
    return _o("--out", help, metavar=metavar, type=_path, default=default)


_NEW_DIR = "output folder (created; must be writable). Default: "
_NO_PROGRESS = _o("--no-progress", "no progress display (default: on stderr when it is a terminal).",
                  action="store_true")
_rate = _typed(lambda s: math.inf if s.strip().lower() == "full" else float(s), lambda v: v > 0,
               "a rate in Hz > 0 or 'full'")
_RECORD_RATE = _o("--record-rate", "rate of the 3-D geometry in run.rrd, Hz > 0, or 'full' (every control "
                  "step; time series always are). Default: 100 (docs: Performance).", metavar="HZ|full",
                  type=_rate)
_BOUNDS = _o("--bounds", "bounds file (required; layout: bounds/paper_mujoco.toml).", metavar="BOUNDS.toml",
             type=_path, required=True)
_SET = dict(dest="overrides", action="append", default=[], metavar="KEY=VALUE")
_POOL = (
    _o("--workers", f"cases run at once, integer >= 1 (not with --scheduler). Default: all cores "
       f"({os.cpu_count() or 1} here).", metavar="N", type=_positive_int),
    _o("--executor", "worker processes (a crash takes only its worker) or threads (same results). Not with "
       "--scheduler. Default: processes.", choices=("processes", "threads"), default="processes"),
    _o("--scheduler", "a running Dask scheduler (e.g. tcp://host:8786). Default: none (local).",
       metavar="ADDRESS"),
)


def _scenario(sim: bool = True) -> list:
    """The scenario file, its shortcut options (sim: those of commands that simulate) and --set."""
    opts = [
        _o("scenario", "scenario file (layout: scenarios/paper.toml). Default: the paper's.", nargs="?",
           metavar="SCENARIO.toml"),
        _o("--plant", "simulated plant (plant.kind): MuJoCo chain, RK4 on the analytic model or Cosserat "
           "rod. Default: the scenario's (paper: mujoco).", choices=PLANTS),
        _o("--actuation", "slave actuation (plant.actuation): position servos, ideal generalized forces T2 "
           "or one-sided muscles. Default: the scenario's (paper: servo).", choices=ACTUATIONS),
        _o("--segments", "rigid segments per section of the MuJoCo chain (plant.segments), integer in [1, "
           "64]. Default: the scenario's (paper: 8).", metavar="N"),
        _o("--duration", "simulated time in s, in (0, 3600], > the metrics' transient. Default: the "
           "scenario's (paper: 20).", metavar="S"),
        _o("--controller", "a built-in controller ('teleop controllers'), 'file.py:Class' or "
           "'package.module:Class'. Default: the scenario's (paper: paper).", metavar="NAME|FILE.py:CLASS"),
        _o("--allow-code", "run a Python controller the scenario file names (trusted files only). Default: "
           "refused.", action="store_true"),
        _o("--seed", "noise seed, integer >= 0. Default: the scenario's (paper: 0).", metavar="N"),
        _o("--snr", "signal-to-noise ratio of the fed-back states, dB in [0, 200], or 'none'. Default: the "
           "scenario's (paper: 40).", metavar="DB|none"),
        _o("--set", "set a scenario field by its dotted key to a TOML value (e.g. plant.segments=16); "
           "repeatable, applied in order after the shortcut options.", **_SET),
    ]
    sim_only = ("--plant", "--duration", "--controller", "--allow-code", "--seed", "--snr")
    return [opt for opt in opts if sim or opt[0] not in sim_only]


_STATUS = "exit status: 0 ok; 1 {one}; 2 invalid input; 130 interrupted."
# (name, help, description, epilog, options (flag, add_argument keywords; exclusive: one group))
_COMMANDS = (
    ("run", "simulate one scenario and write its outputs",
     "Simulate a scenario and write config.toml (first), metrics.json, run.rrd and the PNG figures, also "
     "when the run diverges or is interrupted (Ctrl-C stops cleanly, twice aborts).",
     _STATUS.format(one="diverged / outputs not written / the --view viewer could not be opened"), [
         *_scenario(), _out(_NEW_DIR + "runs/<scenario name>."), _NO_PROGRESS,
         _o("--view", "stream the run to a Rerun viewer: 'native' (a bare --view) or 'web' (served until "
            "Ctrl-C after the run). Default: no viewer.", nargs="?", const="native",
            choices=("native", "web")),
         _o("--view-host", "address of the web viewer (not loopback: served to other machines, no "
            "authentication). Default: 127.0.0.1.", metavar="HOST", default="127.0.0.1"),
         _o("--web-port", "HTTP port of the web viewer, 0 for any free port. Default: 9090.", metavar="N",
            type=_port, default=9090),
         _o("--grpc-port", "data port of the web viewer, 0 for any free port. Default: 9876.", metavar="N",
            type=_port, default=9876),
         _RECORD_RATE]),
    ("check", "simulate a scenario and check acceptance bounds",
     "Like 'run', then list every bound of the bounds file the metrics violate, with value and limit.",
     "exit status: 0 all bounds satisfied; 1 a bound is violated (or the run failed); 2 invalid input; "
     "130 interrupted.", [
         *_scenario(), _BOUNDS, _out("also write the run outputs into this folder. Default: no files."),
         _NO_PROGRESS, _RECORD_RATE]),
    ("models", "export the generated MuJoCo model (MJCF)",
     "Write the MJCF of the scenario's plant master and slave (harness.plant.mujoco_model.export_mjcf).",
     None, [
         *_scenario(sim=False),
         _o("--enforce-cc", "with / without the constant-curvature constraints. Default: the scenario's "
            "(paper: false).", action=argparse.BooleanOptionalAction),
         _out("output MJCF file. Default: mjcf/octarm_<actuation>_n<segments>[_cc].xml.",
              metavar="FILE.xml")]),
    ("sweep", "run a parameter sweep (study file)",
     "Run every case of a study file locally or on a Dask cluster; finished cases are appended to "
     "results.jsonl (a re-run resumes). Also writes summary.csv, plots, study.toml, worst-case recordings.",
     "study file: see studies/*.toml. exit status: 0 every case has a row; 1 cases unfinished, the executor "
     "failed or an output was not written; 2 invalid study, option or output folder; 130 interrupted.", [
         _o("study", "study file describing the sweep.", metavar="STUDY.toml", type=_path),
         _out(_NEW_DIR + "runs/sweeps/<study name> (an existing sweep is resumed)."), *_POOL,
         _o("--max-cases", "refuse a study of more than N cases, integer >= 1. Default: the study's, else "
            "10000.", metavar="N", type=_positive_int),
         _o("--set", "set a field of every case's scenario, after the study's own set (a factor on the key "
            "wins); repeatable. Default: none.", **_SET),
         _o("--case-timeout", "wall-time limit per case, > 0: a case over it becomes a row with status "
            "'error'. Default: no limit.", metavar="SECONDS", type=_positive_float),
         _NO_PROGRESS,
         _o("--allow-code", "run the Python controllers the study names (trusted studies only). Default: "
            "refused.", action="store_true"),
         _o("--view", "do not run: open <out>/recordings/CASE_ID.rrd in a Rerun viewer. Default: run the "
            "sweep.", metavar="CASE_ID")]),
    ("controllers", "list the built-in controllers",
     "List the built-in controllers (name, plant actuations, description). Your own: --controller "
     "path/to/file.py:ClassName.", "Default controller of every scenario: paper (the paper's laws).", []),
    ("cache", "list or prune the compiled-kernel cache",
     "List the compiled-kernel cache folders ($TELEOP_CACHE_DIR, else $XDG_CACHE_HOME/octarm-teleop, else "
     "~/.cache/octarm-teleop) with their sizes, marking those this installation uses. Default: list only.",
     "Removing a folder another installation still uses costs it one recompilation (20-60 s).", [
         _o("--prune", "remove the folders this installation does not use. Default: keep them.",
            action="store_true", exclusive=True),
         _o("--clear", "remove every cache folder (the next run compiles again). Default: keep them.",
            action="store_true", exclusive=True)]),
    ("stability-map", "survival map over null-space gain x rod damping",
     "Run the paper scenario over a grid of k_n (eq. 27-28) and bending viscosity eta_b, free and CC chain, "
     "servo and torque (harness.studies.stability_map). Writes stability_map.md and .png.", None, [
         _o("--duration", "simulated seconds per cell, > 0. Default: 3.", metavar="S", type=_positive_float,
            default=3.0),
         _o("--predicted", "also the map predicted by linearizing each cell of the noise-free torque map "
            "every 0.25 s of its run, next to its simulation (a few minutes). Default: off.",
            action="store_true"),
         _out(_NEW_DIR + "runs/stability_map.", Path("runs/stability_map"))]),
    ("stability", "linear stability of the closed loop at a time point",
     "Run the scenario (no noise) to --at and linearize the closed loop over one control period by central "
     "differences (harness.studies.stability): verdict, spectral radius, least stable modes; writes "
     "spectrum.csv, stability.json and stability.png.",
     "exit status: 0 stable or marginal; 1 unstable, or the run stopped before --at; 2 invalid input.", [
         *_scenario(),
         _o("--at", "time(s) in s, each in [0, 3600], on one run (the files: the least stable). Default: 1.",
            metavar="T[,T...]|START:STOP:STEP", type=_times, default=(1.0,)),
         _o("--fd-step", "relative central-difference step, in (0, 0.01). Default: 1e-6 analytic, 1e-7 "
            "MuJoCo and rod.", metavar="H", type=_positive_float),
         _o("--modes", "least stable modes printed, integer >= 1. Default: 6.", metavar="N",
            type=_positive_int, default=6),
         _out(_NEW_DIR + "runs/stability/<scenario name>.")]),
    ("margin", "robustness margins of a scenario against a bounds file",
     "For each mismatch parameter, the largest deviation each way for which the scenario passes the bounds, "
     "bisected to --rtol (harness.studies.margin); resumable (OUT/results.jsonl). Writes margins.md, "
     "margins.json, margins.png and, with --pair, edge.json / edge.png.",
     "parameters: slave_mass, bending_stiffness, extension_stiffness, master_mass (scales in [0.05, 20]), "
     "material_damping ([0.01, 100]), control_rate ([0.1, 10]), segments (1-64), delay (s, [0, 0.1]), "
     "noise_snr (dB, [0, 200]) or any dotted scenario key as a scale. exit status: 0 margins found; 1 the "
     "executor failed; 2 invalid input or the nominal scenario fails; 130 interrupted.", [
         *_scenario(), _BOUNDS,
         _o("--param", "parameter to search (repeatable). Default: all that apply to the plant.",
            dest="params", action="append", metavar="NAME"),
         _o("--rtol", "relative tolerance of a scale edge, in (0, 1). Default: 0.05.", metavar="R",
            type=_rtol, default=0.05),
         _o("--probes", "points per side checked for a non-monotone edge, integer in [0, 10]. Default: 2.",
            metavar="N", type=_probes, default=2),
         _o("--pair", "also trace the pass/fail edge of two scale parameters in their plane. Default: none.",
            metavar="P1,P2"),
         *_POOL, _out(_NEW_DIR + "runs/margin/<scenario name> (an existing one is resumed)."), _NO_PROGRESS]),
    ("fidelity", "plant-fidelity study over MuJoCo segment counts",
     "Compare the MuJoCo chain with N segments per section against the analytic CC model and with / without "
     "the CC constraints (harness.studies.fidelity). Writes fidelity.md/.csv/.png, fidelity_cc.md/.csv.",
     None, [
         _o("--segments", "segment counts per section, each in [1, 64]. Default: 4,8,16,32.",
            metavar="N,N,...", type=_segment_list, default="4,8,16,32"),
         _o("--samples", "random slave configurations, integer >= 1. Default: 50.", metavar="N",
            type=_positive_int, default=50),
         _o("--seed", "seed of the random configurations, integer >= 0. Default: 0.", metavar="N",
            type=_nonnegative_int, default=0),
         _o("--reference", "compare against the analytic model or the Cosserat rod "
            "(harness.studies.fidelity_reference). Default: analytic.", choices=("analytic", "cosserat"),
            default="analytic"),
         _out(_NEW_DIR + "runs/fidelity.", Path("runs/fidelity")), _NO_PROGRESS]),
    ("findings", "rerun the findings and check their claims",
     "Rerun the shipped findings (findings/*.toml; harness.studies.findings), print claim / measured / holds "
     "and write the findings table and the figures of the runs a finding names.", None, [
         _o("names", "finding names or files. Default: all shipped.", nargs="*", metavar="NAME"),
         _o("--table", "markdown table of all findings (when all run; '<stem>-NAME.md' per finding). "
            "Default: docs/findings-table.md in a checkout, else runs/findings/findings-table.md.",
            metavar="FILE", type=_path),
         _o("--figures", "folder of the figures. Default: docs/figures in a checkout, else "
            "runs/findings/figures.", metavar="DIR", type=_path),
         _o("--no-write", "print only, write nothing. Default: write them.", action="store_true"),
         _o("--list", "list the shipped findings and exit. Default: run them.", action="store_true")]),
)


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
    for name, short, description, epilog, options in _COMMANDS:
        p = sub.add_parser(name, formatter_class=_Formatter, help=short, description=description,
                           epilog=epilog)
        group = None
        for flag, kw in options:
            target = p
            if kw.get("exclusive"):
                group = target = group or p.add_mutually_exclusive_group()
            target.add_argument(flag, **{k: v for k, v in kw.items() if k != "exclusive"})
    return parser
