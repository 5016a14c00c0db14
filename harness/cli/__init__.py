"""`teleop` command-line interface.

    teleop run [SCENARIO.toml] [options]                    simulate one scenario, write outputs
    teleop check [SCENARIO.toml] --bounds BOUNDS.toml ...    simulate and check acceptance bounds
    teleop models [SCENARIO.toml] [--segments N] ...         export the generated MuJoCo model (MJCF)
    teleop sweep STUDY.toml [--out DIR] [--workers N] ...    parameter sweep (local or Dask cluster)
    teleop controllers                                       list the built-in controllers
    teleop fidelity [--segments 4,8,16,32] [--samples N] [--reference analytic|cosserat]   plant fidelity
    teleop cache [--prune | --clear]                         the compiled-kernel cache: list, prune

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
    rc = sweep.main_sweep(study, args.out, args.workers, args.scheduler, not args.no_progress,
                          max_cases=args.max_cases, executor=args.executor)
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


def cmd_stability_map(args: argparse.Namespace) -> int:
    out = prepare_out_dir(args.out)
    smap = _import("harness.studies.stability_map")
    return int(smap.main(out, args.duration))


def cmd_stability(args: argparse.Namespace) -> int:
    from harness.api import stability

    scn = load_from_args(args)
    out = prepare_out_dir(args.out if args.out is not None else Path("runs") / "stability" / scn.name)
    stab = _import("harness.studies.stability")
    if len(args.at) > 1:
        return _stability_along(scn, args, out, stab)
    try:
        res = stability(scn, t=args.at[0], h=args.fd_step, out=out)
    except stab.LinearizationError as exc:
        _err(exc)
        return EXIT_FAIL
    print(res.verdict())
    print(f"{len(res.names)} states; least stable modes (|lambda|, angle, Hz, growth 1/s, dominant):")
    for j in range(min(args.modes, len(res.eigenvalues))):
        lam = res.eigenvalues[j]
        dom = ", ".join(f"{n} {w:.2f}" for n, w in res.dominant(j, 4))
        print(f"  {abs(lam):.6f}  {math.atan2(lam.imag, lam.real):+.4f}  {res.frequency(j):8.2f}  "
              f"{res.growth_rate(j):+9.3g}  {dom}")
    j = res.most_negative()
    lam = res.eigenvalues[j]
    print(f"most negative eigenvalue: {lam.real:+.6f}{lam.imag:+.6f}j ({res.frequency(j):.2f} Hz), on "
          + ", ".join(n for n, _ in res.dominant(j, 4)))
    print(f"wrote {out / 'spectrum.csv'}, {out / 'stability.json'}, {out / 'stability.png'}")
    return EXIT_FAIL if res.verdict_class == "unstable" else EXIT_OK


def _stability_along(scn, args, out: Path, stab) -> int:
    """`teleop stability --at T1,T2,...`: one run, linearized at each time; the least stable one's files."""
    loop = stab.ClosedLoopMap(scn)
    worst, stopped = None, ""
    print("t (s)   radius     class     Hz       dominant")
    for t in args.at:
        try:
            res = stab.linearize(scn, t, args.fd_step, loop=loop)
        except stab.LinearizationError as exc:
            stopped = str(exc)
            break
        dom = ", ".join(n for n, _ in res.dominant(0, 3))
        print(f"{res.t:6.3f}  {res.radius:.6f}  {res.verdict_class:8s}  {res.frequency(0):7.2f}  {dom}")
        if worst is None or res.radius > worst.radius:
            worst = res
    if worst is None:
        _err(stopped)
        return EXIT_FAIL
    _import("harness.studies.stability_report").write_stability(worst, out)
    print(f"least stable: {worst.verdict()}")
    if stopped:
        print(f"stopped: {stopped}")
    print(f"wrote {out / 'spectrum.csv'}, {out / 'stability.json'}, {out / 'stability.png'} "
          f"(t = {worst.t:g} s)")
    return EXIT_FAIL if worst.verdict_class == "unstable" or stopped else EXIT_OK


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
            return EXIT_USAGE
        raise


COMMANDS = {"run": cmd_run, "check": cmd_check, "models": cmd_models, "sweep": cmd_sweep,
            "controllers": cmd_controllers, "fidelity": cmd_fidelity, "cache": cmd_cache,
            "stability-map": cmd_stability_map, "stability": cmd_stability,
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
