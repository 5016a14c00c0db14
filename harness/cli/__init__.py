"""`teleop` command-line interface: each command's function (options: `harness.cli.parser`).  Invalid input
is one ``error: ...`` line and exit 2; back ends are imported lazily (fast ``--help`` and validation)."""

from __future__ import annotations

import argparse
import contextlib
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
from harness.config.metrics import value_unit
from harness.config.runtime import RuntimeOptions, fast_exit, set_gc_thresholds, using_options
from harness.config.textio import jsonable, prepare_out_dir


def _user_error_types() -> tuple[type[BaseException], ...]:
    """The "invalid input" errors (exit 2); back ends' looked up in sys.modules (not imported: not raised)."""
    found = (getattr(sys.modules.get(mod), cls, None) for mod, cls in (
        ("harness.plant.mujoco_model", "PlantModelError"), ("harness.loop.common", "SimulationError")))
    return (ConfigError, ParameterError, *(c for c in found if isinstance(c, type)))


def _err(msg: Any, kind: str = "error") -> None:
    print(f"{kind}: {_one_line(msg)}", file=sys.stderr)


# --plant, ... and their dotted keys
_SHORTCUTS = {"plant": "plant.kind", "actuation": "plant.actuation", "segments": "plant.segments",
              "duration": "duration", "controller": "controller.name", "seed": "seed", "snr": "snr_db"}


def load_from_args(args: argparse.Namespace, extra: Sequence[tuple[str, str]] = (), controller: bool = True):
    """Scenario from the positional file, the shortcut options, `extra` (key=value, label) and --set.
    A controller named on the command line runs; one named in a file needs --allow-code.
    controller=False: the controller is not loaded (no user code is imported)."""
    from harness.api import load_scenario

    pairs: list[tuple[str, str]] = []
    for attr, key in _SHORTCUTS.items():
        value = getattr(args, attr, None)
        if value is not None:
            text = str(value).strip()
            text = json.dumps(text) if attr in ("plant", "actuation", "controller") else text  # TOML strings
            pairs.append((f"{key}={text}", f"--{attr} {value}"))
    pairs += extra
    pairs += [(t, f"--set {t if len(t) <= 80 else t[:77] + '...'}") for t in args.overrides]
    return load_scenario(args.scenario, [t for t, _ in pairs], labels=[label for _, label in pairs],
                         controller=controller, allow_code=bool(getattr(args, "allow_code", False)) or None)


def _fmt_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if v == 0 or 1e-3 <= abs(v) < 1e4 else f"{v:.3e}"
    return str(v)


_SUMMARY_KEYS = ("e1_rms", "e1_max", "e2_rms", "e2_max", "e2_plant_rms", "e2_plant_max", "beta_min",
                 "mujoco_warnings")  # metrics printed in the run summary


def _summary_items(metrics: dict[str, Any]) -> list[str]:
    """"name = value unit" of each measured summary metric (None/NaN skipped; unit: `value_unit`)."""
    return [f"{k} = {_fmt_value(metrics[k])}{' ' + value_unit(k) if value_unit(k) else ''}"
            for k in _SUMMARY_KEYS if jsonable(metrics.get(k)) is not None]


def _simulate_and_write(args: argparse.Namespace, scn, out: Path | None, live=None):
    """`harness.api.run_scenario` (live: a `LiveView` fed chunk by chunk), the summary, a warning per
    output that could not be written and the hint of a known failure.  Returns the `RunResult`."""
    from harness.api import run_scenario

    res = run_scenario(scn, out, not args.no_progress, handle_signals=True, record_rate=args.record_rate,
                       on_chunk=live.on_chunk if live is not None else None)
    traj, metrics, p = res.traj, res.metrics, scn.plant
    if live is not None:
        live.finish(traj)
    plant = p.kind + (f", {p.segments} segments/section, {p.actuation}" if p.kind == "mujoco" else "")
    t_end = float(traj.t[-1]) if len(traj) else 0.0
    print(f"run '{scn.name}': status {traj.status} - {len(traj)} of {scn.n_steps} steps, t = {t_end:.3f} s "
          f"(plant {plant})")
    if traj.message:
        print(f"  message: {_one_line(traj.message)}")
    if metrics:
        items = _summary_items(metrics)
        for i in range(0, len(items), 3):
            print("  " + "   ".join(items[i:i + 3]))
    if out is not None:
        names = ", ".join(f.name if f.parent == out else str(f) for f in res.written)
        print(f"  outputs in {out}/: {names or '(none)'}")
    for f in res.failures:
        _err(f"could not produce {f}", "warning")
    hint = failure_hint(scn, res.traj)
    if hint:
        print(hint, file=sys.stderr)
    return res


# Settings that run the paper scenario in torque actuation on the MuJoCo plant (each checked by
# tests/test_controller_safety.py): (applies to this scenario, option, what it is)
_TORQUE_FIXES = (
    (lambda s: not s.plant.enforce_cc, "--set plant.enforce_cc=true", "the CC chain"),
    (lambda s: max(s.plant.bending_viscosity) < 1.0, "--set plant.bending_viscosity=[1.0,1.0,1.0]",
     "10x the default bending damping"),
    (lambda s: s.gains.kn > 60.0, "--set gains.kn=60", "a lower null-space gain"),
    (lambda s: s.sensing.dq2_cutoff is None, "--set sensing.dq2_cutoff=200",
     "a 200 Hz low-pass on the sensed dq2"),
)


def failure_hint(scn, traj) -> str | None:
    """One line saying what to change when a run failed for a known reason (torque actuation on the
    MuJoCo free chain diverges with the paper's gains), else None."""
    p = scn.plant
    if traj.status != "diverged" or p.kind != "mujoco" or p.actuation != "torque" or p.enforce_cc:
        return None
    fixes = [f"{opt} ({what})" for applies, opt, what in _TORQUE_FIXES if applies(scn)]
    runs = "; settings that run the paper scenario: " + ", ".join(fixes) if fixes else ""
    return (f"hint: torque actuation on the free chain diverges: the stability map ('teleop stability-map') "
            f"puts k_n = {scn.gains.kn:g} past the sampled-data limit of a non-CC mode at the section "
            f"junction{runs}")


def _run_exit_code(res, wrote: bool = True, status: bool = True) -> int:
    """The exit status of a run: interrupted, (status) not "ok", an output not written, else ok."""
    traj = res.traj
    if res.interrupted:
        t_end = float(traj.t[-1]) if len(traj) else 0.0
        note = "; outputs written for the completed part" if wrote else ""
        _err(f"run interrupted at t = {t_end:.3f} s{note}")
        return EXIT_INTERRUPTED
    if status and traj.status != "ok":
        _err(f"run {traj.status}: {traj.message or 'no message'}")
        return EXIT_FAIL
    if res.failures:
        _err(f"{len(res.failures)} output(s) could not be produced (see warnings above)")
        return EXIT_FAIL
    return EXIT_OK


def cmd_run(args: argparse.Namespace) -> int:
    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / scn.name)
    live = None
    if args.view:
        from harness.output import viewer

        try:
            live = viewer.LiveView.open(args.view, scn, host=args.view_host, web_port=args.web_port,
                                        grpc_port=args.grpc_port)
        except viewer.ViewerUnavailable as e:
            _err(f"{e} (nothing was run, no outputs written)")
            return EXIT_FAIL
        if args.view == "web" and not viewer.is_loopback(args.view_host):
            _err(f"--view-host {args.view_host}: the web viewer and the run's data are served to every "
                 f"machine that can reach this address, without authentication", "warning")
        if live.url:
            print(f"web viewer: {live.url} (listening on {live.listen})", file=sys.stderr)
    try:
        res = _simulate_and_write(args, scn, out, live)
        rc = _run_exit_code(res)
        if live is not None and live.failed:
            _err(f"live view: {live.failed}", "warning")
        if live is not None and live.url and not res.interrupted:
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
    res = _simulate_and_write(args, scn, out)
    if res.interrupted or res.traj.status == "error":  # an error is no measurement, whatever the bounds
        return _run_exit_code(res, wrote=out is not None)
    if res.metrics is None:
        _err(f"no metrics could be computed, bounds not checked ({(res.failures or ['unknown'])[0]})")
        return EXIT_FAIL
    violations = check_bounds(res.metrics, bounds)
    if violations:
        print(f"check against {args.bounds}: {len(violations)} bound(s) violated")
        for v in violations:
            print(f"  FAIL {v}")
        return EXIT_FAIL
    print(f"check against {args.bounds}: all bounds satisfied")
    return _run_exit_code(res, status=False)


def cmd_models(args: argparse.Namespace) -> int:
    extra = []
    if args.enforce_cc is not None:
        extra.append((f"plant.enforce_cc={str(args.enforce_cc).lower()}",
                      "--enforce-cc" if args.enforce_cc else "--no-enforce-cc"))
    scn = load_from_args(args, extra, controller=False)  # a model export never imports a controller
    p = scn.plant
    path = args.out if args.out is not None else Path(
        "mjcf") / f"octarm_{p.actuation}_n{p.segments}{'_cc' if p.enforce_cc else ''}.xml"
    if path.is_dir():
        raise ConfigError(f"--out = '{path}': is a directory, expected a file name", path="--out")
    prepare_out_dir(path.parent if str(path.parent) else Path("."))
    from harness.plant.mujoco_model import export_mjcf

    result = export_mjcf(scn.plant_master, scn.plant_slave, p, path)
    print(f"wrote {result if isinstance(result, (str, Path)) else path} "
          f"({p.segments} segments/section, {p.actuation} actuation, enforce_cc={str(p.enforce_cc).lower()})")
    return EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    from harness.config.assets import shipped
    from harness.studies import sweep

    study: Path = shipped(args.study, "studies")
    if not study.exists():
        raise ConfigError(f"study file not found: {study}", path=str(study))
    if not study.is_file():
        raise ConfigError(f"study file {study}: not a regular file (a folder, named pipe, device or socket "
                          "is not read)", path=str(study))
    if args.view is None:  # validates the study, then creates and checks the output folder
        return sweep.main_sweep(study, args.out, args.workers, args.scheduler, not args.no_progress,
                                max_cases=args.max_cases, executor=args.executor, overrides=args.overrides,
                                case_timeout=args.case_timeout, allow_code=args.allow_code)
    case_id = args.view  # open the case's recording in a spawned Rerun viewer
    out = args.out if args.out is not None else Path("runs") / "sweeps" / sweep.load_study(study).name
    path = out / "recordings" / f"{case_id}.rrd"
    if not path.is_file():
        have = ", ".join(sorted(p.stem for p in (out / "recordings").glob("*.rrd"))) or "none"
        raise ConfigError(f"--view {case_id}: no recording {path} (recorded cases: {have}; re-run the case "
                          "with 'teleop run --view')", path="--view")
    from harness.output import viewer

    try:
        cmd = viewer.spawn_recording_viewer(path)
    except viewer.ViewerUnavailable as e:
        _err(f"--view {case_id}: {e}")
        return EXIT_FAIL
    print(f"opened {path} ({' '.join(cmd)})")
    return EXIT_OK


def cmd_controllers(args: argparse.Namespace) -> int:  # noqa: ARG001
    from harness.config.controller import describe_builtins

    items = describe_builtins()
    width = max(len(n) for n, _, _ in items)
    for name, desc, acts in items:
        print(f"{name:<{width}}  [{'/'.join(acts):<12}]  {desc}")
    print("your own: --controller path/to/file.py:ClassName or package.module:ClassName "
          "(see controllers/interface.py)")
    return EXIT_OK


def cmd_cache(args: argparse.Namespace) -> int:
    from harness.loop import cache_admin as admin
    from harness.loop.fast import cache_root

    root = cache_root()
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


def cmd_fidelity(args: argparse.Namespace) -> int:
    out = prepare_out_dir(args.out)
    from harness.studies import fidelity, fidelity_reference

    if args.reference == "cosserat":
        return fidelity_reference.main_reference(args.segments, out, not args.no_progress, args.seed)
    return fidelity.main_fidelity(args.segments, out, not args.no_progress, args.samples, args.seed)


def cmd_findings(args: argparse.Namespace) -> int:
    from harness.studies import findings

    if args.list:
        for name in findings.available():
            print(f"{name:32s} {findings.load_finding(name).title}")
        return EXIT_OK
    results = findings.run_findings(args.names, keep_trajectories=not args.no_write,
                                    on_result=lambda r: print(findings.report_text(r), flush=True))
    if not args.no_write:
        base = Path("docs") if Path("mkdocs.yml").is_file() else Path("runs/findings")
        # the table of all findings only when all of them ran; one table per finding always
        for path in findings.write_outputs(results, args.table or base / "findings-table.md",
                                           args.figures or base / "figures", combined=not args.names):
            print(f"wrote {path}")
    held = sum(r.holds for r in results)
    print(f"{held} of {len(results)} findings hold")
    return EXIT_OK if held == len(results) else EXIT_FAIL


def cmd_stability_map(args: argparse.Namespace) -> int:
    from harness.studies import stability_map

    return stability_map.main(prepare_out_dir(args.out), args.duration, args.predicted)


def cmd_stability(args: argparse.Namespace) -> int:
    from harness.api import stability
    from harness.studies import stability as stab
    from harness.studies import stability_report as report

    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / "stability" / scn.name)
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
    from harness.studies.margin import servo_note
    from harness.studies.margin_report import margins_markdown

    scn = load_from_args(args)
    bounds = load_bounds(args.bounds)
    pair = None
    if args.pair is not None:
        pair = tuple(x.strip() for x in args.pair.split(","))
        if len(pair) != 2 or not all(pair):
            raise ConfigError(f"--pair = {args.pair!r}: expected two parameter names, P1,P2", path="--pair")
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / "margin" / scn.name)
    note = servo_note(scn, args.params or ["slave_mass"])
    if note:
        _err(note, "warning")
    rows, edge = margins(scn, bounds=bounds, params=args.params, rtol=args.rtol, probes=args.probes, out=out,
                         workers=args.workers, scheduler=args.scheduler, executor=args.executor, pair=pair,
                         say=(lambda s: None) if args.no_progress else (lambda s: print(s, file=sys.stderr)))
    if rows:
        print(margins_markdown(rows))
    for r in edge or ():
        print(f"edge {r['angle_deg']:5.0f} deg: {pair[0]} x{r['p1']:.4g}, {pair[1]} x{r['p2']:.4g}"
              f" ({r['first_bound'] or 'range end'})")
    print(f"wrote {out}")
    return EXIT_OK


COMMANDS = {"run": cmd_run, "check": cmd_check, "models": cmd_models, "sweep": cmd_sweep,
            "controllers": cmd_controllers, "fidelity": cmd_fidelity, "cache": cmd_cache,
            "findings": cmd_findings, "stability-map": cmd_stability_map, "stability": cmd_stability,
            "margin": cmd_margin}


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
    except OSError as e:  # a file that could not be read or written (bad path, full disk): one line
        where = f"{e.filename}: " if e.filename else ""
        _err(f"{where}{e.strerror or e}")
        return EXIT_USAGE
    except Exception as e:
        if isinstance(e, _user_error_types()):
            _err(e)
            return getattr(e, "exit_code", EXIT_USAGE)  # a controller's own code failing: 1
        raise


def prepare_process() -> None:
    """What `teleop` sets up before `main()` and before MuJoCo loads: `GC_THRESHOLDS` and MuJoCo's OpenGL
    off unless MUJOCO_GL says otherwise (the harness draws with Rerun and matplotlib)."""
    os.environ.setdefault("MUJOCO_GL", "disable")
    set_gc_thresholds()


def entry() -> NoReturn:
    """The `teleop` command (console script and `python -m harness.cli`): `prepare_process()`, `main()`,
    then `fast_exit` (atexit handlers, no teardown)."""
    prepare_process()
    fast_exit(main())
