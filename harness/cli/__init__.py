"""`teleop` command-line interface.

    teleop run [SCENARIO.toml] [options]                    simulate one scenario, write outputs
    teleop check [SCENARIO.toml] --bounds BOUNDS.toml ...    simulate and check acceptance bounds
    teleop models [SCENARIO.toml] [--segments N] ...         export the generated MuJoCo model (MJCF)
    teleop sweep STUDY.toml [--out DIR] [--workers N] ...    parameter sweep (local or Dask cluster)
    teleop controllers                                       list the built-in controllers
    teleop fidelity [--segments 4,8,16,32] [--samples N] [--reference analytic|cosserat]   plant fidelity
    teleop cache [--prune | --clear]                         the compiled-kernel cache: list, prune
    teleop findings [NAME ...]                               rerun the findings, check their claims

Exit status: 0 success; 1 the run failed (diverged, an output could not be written), a bound was
violated or the viewer of `--view` could not be opened; 2 invalid input (scenario, bounds, option,
output folder; a file that cannot be written before anything ran); 130 interrupted (SIGINT/SIGTERM).
Invalid input is reported as a single ``error: ...`` line on stderr, never a traceback.

The simulation back ends are imported lazily so that ``--help`` and input validation are fast.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from controllers.params import ParameterError
from harness.cli.parser import EXIT_FAIL, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, build_parser
from harness.cli.parser import one_line as _one_line
from harness.config.errors import ConfigError
from harness.config.runtime import RuntimeOptions, fast_exit, set_gc_thresholds, using_options
from harness.config.textio import jsonable, prepare_out_dir

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




def _err(msg: Any) -> None:
    print(f"error: {_one_line(msg)}", file=sys.stderr)


def _warn(msg: Any) -> None:
    print(f"warning: {_one_line(msg)}", file=sys.stderr)


# ---------------------------------------------------------------------------------------------
# argument parsing
# ---------------------------------------------------------------------------------------------
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


def load_from_args(args: argparse.Namespace, extra: Sequence[tuple[str, str]] = (), controller: bool = True):
    """Scenario from the positional file, the shortcut options, `extra` (key=value, label) and --set.
    The command line is the user's say-so for a Python controller; a file naming one needs --allow-code.
    controller=False: the controller is not loaded (no user code is imported)."""
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
    return load_scenario(args.scenario, overrides, labels=labels, controller=controller,
                         allow_code=bool(getattr(args, "allow_code", False)) or None)


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


class _ViewerUnavailable(RuntimeError):
    """`--view` could not open its viewer (one line)."""


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


# Settings that run the paper scenario in torque actuation on the MuJoCo plant (each checked for 5 s by
# tests/test_controller_safety.py::test_every_setting_the_torque_hint_suggests_runs): (applies to this
# scenario, option, what it is)
_TORQUE_FIXES = (
    (lambda s: not s.plant.enforce_cc, "--set plant.enforce_cc=true", "the CC chain"),
    (lambda s: max(s.plant.bending_viscosity) < 1.0, "--set plant.bending_viscosity=[1.0,1.0,1.0]",
     "10x the default bending damping"),
    (lambda s: s.gains.kn > 60.0, "--set gains.kn=60", "a lower null-space gain"),
)


def failure_hint(scn, traj) -> str | None:
    """One line saying what to change when a run failed for a known reason, else None.  Known: torque
    actuation on the MuJoCo free chain diverges with the paper's gains (README, stability map)."""
    p = scn.plant
    if traj.status != "diverged" or p.kind != "mujoco" or p.actuation != "torque" or p.enforce_cc:
        return None
    fixes = [f"{opt} ({what})" for applies, opt, what in _TORQUE_FIXES if applies(scn)]
    runs = "; settings that run the paper scenario: " + ", ".join(fixes) if fixes else ""
    return (f"hint: torque actuation on the free chain diverges: the stability map ('teleop stability-map') "
            f"puts k_n = {scn.gains.kn:g} past the sampled-data limit of a non-CC mode at the section "
            f"junction{runs}")


def _print_hint(scn, traj) -> None:
    hint = failure_hint(scn, traj)
    if hint:
        print(hint, file=sys.stderr)


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
def _open_live_view(args: argparse.Namespace, scn):
    """The live view of `teleop run --view` (None without --view); ViewerUnavailable before anything runs."""
    if not args.view:
        return None
    viewer = _import("harness.output.viewer")
    try:
        live = viewer.LiveView.open(args.view, scn, host=args.view_host, web_port=args.web_port,
                                    grpc_port=args.grpc_port)
    except viewer.ViewerUnavailable as e:
        raise _ViewerUnavailable(str(e)) from None
    if args.view == "web" and not viewer.is_loopback(args.view_host):
        _warn(f"--view-host {args.view_host}: the web viewer and the run's data are served to every machine "
              f"that can reach this address, without authentication")
    if live.url:
        print(f"web viewer: {live.url} (listening on {live.listen})", file=sys.stderr)
    return live


def cmd_run(args: argparse.Namespace) -> int:
    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / scn.name)
    try:
        live = _open_live_view(args, scn)
    except _ViewerUnavailable as e:
        _err(f"{e} (nothing was run, no outputs written)")
        return EXIT_FAIL
    try:
        traj, _, failures, interrupted = _simulate_and_write(scn, out, progress=not args.no_progress,
                                                             live=live, record_rate=args.record_rate)
        rc = _run_exit_code(traj, failures, interrupted)
        _print_hint(scn, traj)
        if live is not None:
            if live.failed:
                _warn(f"live view: {live.failed}")
            if live.url and not interrupted:
                print(f"serving the web viewer at {live.url} - Ctrl-C to stop", file=sys.stderr)
                with contextlib.suppress(KeyboardInterrupt):
                    while not threading.Event().wait(0.5):  # short waits: Ctrl-C is handled promptly
                        pass
    finally:
        if live is not None:
            live.close()
    return rc


def cmd_check(args: argparse.Namespace) -> int:
    from harness.config.bounds import check_bounds, load_bounds

    scn = load_from_args(args)
    bounds = load_bounds(args.bounds)
    out = prepare_out_dir(args.out) if args.out is not None else None
    traj, metrics, failures, interrupted = _simulate_and_write(scn, out, progress=not args.no_progress,
                                                               record_rate=args.record_rate)
    _print_hint(scn, traj)
    if interrupted or traj.status == "error":  # an error is no measurement, whatever the bounds allow
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
    scn = load_from_args(args, extra, controller=False)  # a model export never imports a controller
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
    if not study.exists():
        raise ConfigError(f"study file not found: {study}", path=str(study))
    if not study.is_file():
        raise ConfigError(f"study file {study}: not a regular file (a folder, named pipe, device or socket "
                          "is not read)", path=str(study))
    if args.view is not None:
        return _view_case(study, args.out, args.view)
    sweep = _import("harness.studies.sweep")  # validates the study, then creates and checks the output folder
    rc = sweep.main_sweep(study, args.out, args.workers, args.scheduler, not args.no_progress,
                          max_cases=args.max_cases, executor=args.executor, overrides=args.overrides,
                          case_timeout=args.case_timeout, allow_code=args.allow_code)
    return int(rc) if isinstance(rc, int) and not isinstance(rc, bool) else EXIT_OK


def cmd_controllers(args: argparse.Namespace) -> int:  # noqa: ARG001
    registry = _import("harness.config.controller")
    items = registry.describe_builtins()
    width = max(len(n) for n, _, _ in items)
    for name, desc, acts in items:
        print(f"{name:<{width}}  [{'/'.join(acts):<12}]  {desc}")
    print("your own: --controller path/to/file.py:ClassName or package.module:ClassName "
          "(see controllers/interface.py)")
    return EXIT_OK


def cmd_cache(args: argparse.Namespace) -> int:
    admin = _import("harness.loop.cache_admin")
    root = _import("harness.loop.fast").cache_root()
    items = admin.folders(root)
    if args.prune or args.clear:
        gone = [f for f in items if args.clear or not f.current]
        freed, errors = admin.remove(gone)
        for e in errors:
            _err(f"could not remove {e}")
        print(f"{root}: removed {len(gone) - len(errors)} of {len(items)} folder(s), "
              f"{admin.mib(freed)} freed")
        return EXIT_FAIL if errors else EXIT_OK
    if not items:
        print(f"{root}: no compiled kernels yet")
        return EXIT_OK
    for f in items:
        print(f"{admin.mib(f.size):>10}  {'current' if f.current else 'stale  '}  {f.path.name}")
    stale = [f for f in items if not f.current]
    hint = f" ({admin.mib(sum(f.size for f in stale))}): 'teleop cache --prune' removes them" if stale else ""
    total = admin.mib(sum(f.size for f in items))
    print(f"{root}: {len(items)} folder(s), {total}; {len(stale)} stale{hint}")
    return EXIT_OK


def _view_case(study: Path, out: Path | None, case_id: str) -> int:
    """`teleop sweep STUDY --view CASE_ID`: open a case's recording in a spawned Rerun viewer."""
    if out is None:
        out = Path("runs") / "sweeps" / _import("harness.studies.sweep").load_study(study).name
    path = out / "recordings" / f"{case_id}.rrd"
    if not path.is_file():
        have = sorted(p.stem for p in (out / "recordings").glob("*.rrd"))
        raise ConfigError(f"--view {case_id}: no recording {path} (recorded cases: "
                          f"{', '.join(have) or 'none'}; re-run the case with 'teleop run --view')",
                          path="--view")
    viewer = _import("harness.output.viewer")
    try:
        cmd = viewer.spawn_recording_viewer(path)
    except viewer.ViewerUnavailable as e:
        _err(f"--view {case_id}: {e}")
        return EXIT_FAIL
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
        report = _import("harness.studies.fidelity_reference")
        rc = report.main_reference(segments, out, not args.no_progress, args.seed)
    else:
        fidelity = _import("harness.studies.fidelity")
        rc = fidelity.main_fidelity(segments, out, not args.no_progress, args.samples, args.seed)
    return int(rc) if isinstance(rc, int) and not isinstance(rc, bool) else EXIT_OK


def cmd_findings(args: argparse.Namespace) -> int:
    findings = _import("harness.studies.findings")
    if args.list:
        for name in findings.available():
            print(f"{name:32s} {findings.load_finding(name).title}")
        return EXIT_OK
    results = findings.run_findings(args.names, keep_trajectories=not args.no_write,
                                    on_result=lambda r: print(findings.report_text(r), flush=True))
    if not args.no_write:
        base = Path("docs") if Path("mkdocs.yml").is_file() else Path("runs/findings")
        table = args.table or base / "findings-table.md"
        figures = args.figures or base / "figures"
        # the table of all findings only when all of them ran; one table per finding always
        for path in findings.write_outputs(results, table, figures, combined=not args.names):
            print(f"wrote {path}")
    held = sum(r.holds for r in results)
    print(f"{held} of {len(results)} findings hold")
    return EXIT_OK if held == len(results) else EXIT_FAIL


def cmd_stability_map(args: argparse.Namespace) -> int:
    out = prepare_out_dir(args.out)
    smap = _import("harness.studies.stability_map")
    return int(smap.main(out, args.duration))


def cmd_stability(args: argparse.Namespace) -> int:
    from harness.api import stability

    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / "stability" / scn.name)
    stab, report = _import("harness.studies.stability"), _import("harness.studies.stability_report")
    try:
        if len(args.at) > 1:  # one run, linearized at each time; the least stable one's files
            res = report.least_stable_along(scn, args.at, args.fd_step, out)
        else:
            res = stability(scn, t=args.at[0], h=args.fd_step, out=out)
            report.print_modes(res, args.modes)
    except stab.LinearizationError as exc:
        _err(exc)
        return EXIT_FAIL
    print(f"wrote {out / 'spectrum.csv'}, {out / 'stability.json'}, {out / 'stability.png'} "
          f"(t = {res.t:g} s)")
    return EXIT_FAIL if res.verdict_class == "unstable" or res.stopped else EXIT_OK


def cmd_margin(args: argparse.Namespace) -> int:
    from harness.api import margins
    from harness.config.bounds import load_bounds

    scn = load_from_args(args)
    bounds = load_bounds(args.bounds)
    if not 0 < args.rtol < 1:
        raise ConfigError(f"--rtol = {args.rtol}: expected a relative tolerance in (0, 1)", path="--rtol")
    if args.probes > 10:
        raise ConfigError(f"--probes = {args.probes}: expected an integer in [0, 10]", path="--probes")
    pair = None
    if args.pair is not None:
        pair = tuple(x.strip() for x in args.pair.split(","))
        if len(pair) != 2 or not all(pair):
            raise ConfigError(f"--pair = {args.pair!r}: expected two parameter names, P1,P2", path="--pair")
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / "margin" / scn.name)
    say = (lambda s: None) if args.no_progress else (lambda s: print(s, file=sys.stderr))  # noqa: E731
    note = _import("harness.studies.margin").servo_note(scn, args.params or ["slave_mass"])
    if note:
        _warn(note)
    rows, edge = margins(scn, bounds=bounds, params=args.params, rtol=args.rtol, probes=args.probes, out=out,
                         workers=args.workers, scheduler=args.scheduler, executor=args.executor, pair=pair,
                         say=say)
    if rows:
        print(_import("harness.studies.margin_report").margins_markdown(rows))
    if edge is not None:
        for r in edge:
            print(f"edge {r['angle_deg']:5.0f} deg: {pair[0]} x{r['p1']:.4g}, {pair[1]} x{r['p2']:.4g}"
                  f" ({r['first_bound'] or 'range end'})")
    print(f"wrote {out}")
    return EXIT_OK


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
        with using_options(RuntimeOptions.from_env()):  # the TELEOP_* switches, read once
            return COMMANDS[args.command](args)
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
            return getattr(e, "exit_code", EXIT_USAGE)  # a controller's own code failing: 1
        raise


COMMANDS = {"run": cmd_run, "check": cmd_check, "models": cmd_models, "sweep": cmd_sweep,
            "controllers": cmd_controllers, "fidelity": cmd_fidelity, "cache": cmd_cache,
            "findings": cmd_findings, "stability-map": cmd_stability_map, "stability": cmd_stability,
            "margin": cmd_margin}


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())


def prepare_process() -> None:
    """What the `teleop` command sets up before `main()` (also used by benchmarks/bench_core.py, so that
    it measures the command as users run it): the collector thresholds
    `harness.config.runtime.GC_THRESHOLDS`, and MuJoCo's OpenGL rendering off unless MUJOCO_GL says
    otherwise (the harness draws with Rerun and matplotlib; `import mujoco` then skips looking for
    GLFW, ~0.1 s).  Call it before MuJoCo is imported; sweep workers inherit the environment."""
    os.environ.setdefault("MUJOCO_GL", "disable")
    set_gc_thresholds()


def entry() -> NoReturn:
    """The `teleop` command (console script and `python -m harness.cli`): `prepare_process()`, `main()`,
    then `fast_exit` (atexit handlers, no teardown)."""
    prepare_process()
    fast_exit(main())
