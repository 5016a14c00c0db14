"""Mismatch sweeps (`teleop sweep`): run every case of a study through an executor, append each row as it
finishes, resume, write the summary.  Outputs (docs/guide/sweeps.md): results.jsonl (append-only, one
fsynced line per case, a torn tail ignored), study.toml (the resolved study), summary.csv and plots,
recordings/<case_id>.rrd of the worst cases, .lock; nothing is read or written through a symbolic link."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from harness.config.errors import ConfigError
from harness.config.load import scenario_to_dict
from harness.config.runtime import progress_bar_class
from harness.config.scenario import Scenario
from harness.config.textio import OutputError, describe_os_error, jsonable, prepare_out_dir, write_atomic
from harness.studies.cases import expand_cases, load_base
from harness.studies.executor import (
    Runner,
    SweepError,
    check_case_timeout,
    pick_executor,
    run_case,
    run_cases,
)
from harness.studies.study import (
    DEFAULT_OUT_ROOT,
    METRIC_LABELS,
    METRIC_NAMES,
    Case,
    Study,
    check_case_count,
    check_max_cases,
    check_study_name,
    is_real,
    load_study,
)
from harness.studies.summary import write_summary

log = logging.getLogger(__name__)

__all__ = ["METRIC_LABELS", "METRIC_NAMES", "RESULTS", "Case", "Study", "SweepError", "SweepInterrupted",
           "SweepResult", "expand_cases", "load_study", "main_sweep", "read_results", "run_case", "run_sweep"]


RESULTS = "results.jsonl"  # the results table in a sweep's output folder


def read_results(path: str | os.PathLike) -> dict[str, dict]:
    """Rows of a results.jsonl by case id (first occurrence wins).  A last line without its newline (torn
    by a crash) is ignored; other unreadable lines are skipped with a warning."""
    path = Path(path)
    if not path.exists():
        return {}
    rows: dict[str, dict] = {}
    lines = path.read_bytes().split(b"\n")
    if lines[-1].strip():
        log.warning("%s: ignoring a torn last line (%d bytes)", path, len(lines[-1]))
    for no, line in enumerate(lines[:-1], 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError:
            row = None
        if not isinstance(row, dict) or not isinstance(row.get("case_id"), str):
            log.warning("%s:%d: unreadable row skipped", path, no)
            continue
        rows.setdefault(row["case_id"], row)
    return rows


def refuse_link(path: Path) -> None:
    """ConfigError (one line) if `path` is a symbolic link."""
    if path.is_symlink():
        raise ConfigError(f"{path}: is a symbolic link; a sweep does not read or write results through a "
                          "link (remove it, or choose another --out)", path=str(path))


def open_no_follow(path: Path, flags: int, mode: int = 0o644) -> int:
    """os.open that refuses a symbolic link at `path` (O_NOFOLLOW where the system has it)."""
    refuse_link(path)
    try:
        return os.open(path, flags | getattr(os, "O_NOFOLLOW", 0), mode)
    except OSError as e:
        refuse_link(path)  # planted between the check and the open
        raise OSError(e.errno, e.strerror, str(path)) from None


class ResultsWriter:
    """Appends rows to results.jsonl, one fsynced line each, after cutting off a torn tail."""

    def __init__(self, path: Path):
        self._fh = os.fdopen(open_no_follow(path, os.O_RDWR | os.O_CREAT), "r+b")
        data = self._fh.read()
        self._fh.truncate(data.rfind(b"\n") + 1)
        self._fh.seek(0, os.SEEK_END)

    def append(self, row: dict) -> None:
        self._fh.write((json.dumps(row, allow_nan=False) + "\n").encode())
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


def make_row(case: Case, result: dict) -> dict:
    """The results.jsonl row of a case's result (`executor.run_case`)."""
    return {"case_id": case.case_id, "params": case.params, "status": str(result.get("status", "error")),
            "message": str(result.get("message", "")), "metrics": jsonable(result.get("metrics") or {}),
            "wall_time": jsonable(result.get("wall_time")), "traceback": str(result.get("traceback", ""))}


class OutputLock:
    """Exclusive lock on the output folder (none where the system has no fcntl)."""

    def __init__(self, out: Path):
        self._fh = os.fdopen(open_no_follow(out / ".lock", os.O_WRONLY | os.O_CREAT), "w")
        try:
            import fcntl

            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:
            pass
        except OSError:
            self._fh.close()
            raise ConfigError(f"{out} is in use by another sweep") from None

    def release(self) -> None:
        try:  # explicitly: a forked worker still holding the descriptor must not keep the lock
            import fcntl

            fcntl.flock(self._fh, fcntl.LOCK_UN)
        except (ImportError, OSError, ValueError):
            pass
        self._fh.close()


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C / SIGTERM during a sweep; `.result` holds the partial SweepResult (rows are on disk)."""

    def __init__(self, result: SweepResult):
        super().__init__(f"sweep interrupted: {len(result.rows)} of {len(result.cases)} cases done")
        self.result = result


@dataclass
class SweepResult:
    study: Study
    out: Path
    cases: list[Case]
    rows: dict[str, dict]  # case id -> row, for this study's cases that have one
    ran: int = 0  # cases run by this call
    skipped: int = 0  # cases already in the table
    unfinished: int = 0  # cases that came back "interrupted" (not written; they re-run)
    recordings: list[Path] = dataclasses.field(default_factory=list)
    summary: list[Path] = dataclasses.field(default_factory=list)
    executor: str = ""  # "processes" | "threads" | "dask": what ran the cases (`pick_executor`)
    failures: list[str] = dataclasses.field(default_factory=list)  # outputs that could not be written
    # wall seconds of this call's phases: "setup" (study, cases, output folder, workers), "cases" (first
    # submit to last result), "recordings" (the worst cases re-run), "summary" (summary.csv and plots)
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    hidden: list[str] = dataclasses.field(default_factory=list)  # factors a servo plant hides

    @property
    def complete(self) -> bool:
        return all(c.case_id in self.rows for c in self.cases)

    def counts(self) -> dict[str, int]:
        return dict(Counter(r["status"] for r in self.rows.values()))


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


def _study_document(study: Study, base: Scenario) -> dict:
    st: dict[str, Any] = {"name": study.name, "set": list(study.set), "metrics": list(study.metrics)}
    if study.description:
        st["description"] = study.description
    if study.record:
        st["record"] = dataclasses.asdict(study.record)
    factors = [{"name": f.name, "param": f.param, f.mode: f.dist if f.is_random else list(f.levels)}
               for f in study.factors]
    sampling: dict[str, Any] = {"mode": study.mode, "seed": study.seed, "max_cases": study.max_cases}
    if study.n is not None:
        sampling["n"] = study.n
    return {"study": st, "sampling": sampling, "factor": factors, "scenario": scenario_to_dict(base)}


# slave dynamics parameters the stiff position servos of the MuJoCo chain hide (docs/plants.md, actuations)
HIDDEN_BY_SERVO = ("plant.slave.masses", "plant.slave.slice_inertia", "plant.slave.extension_damping",
                   "plant.slave.bending_damping", "plant.extension_viscosity", "plant.bending_viscosity")


def hidden_factors(study: Study, cases: Sequence[Case]) -> list[str]:
    """The study's factors that vary slave dynamics on the servo-actuated MuJoCo chain."""
    servo = any(c.scenario.plant.kind == "mujoco" and c.scenario.plant.actuation == "servo"
                for c in cases)
    return [f.name for f in study.factors if servo and ".".join(f.path) in HIDDEN_BY_SERVO]


def hidden_warning(names: Sequence[str]) -> str:
    return (f"warning: factor(s) {', '.join(map(repr, names))} vary the slave's dynamics on a servo-actuated "
            "plant, whose position servos hide them; use plant.actuation = \"torque\" or \"muscle\" to "
            "see their effect")


def sensitivity(result: SweepResult, name: str, metric: str = "e2_rms") -> str:
    """The measured spread of `metric` over the levels of factor `name` (finite rows only)."""
    pts = []
    for r in result.rows.values():
        x, y = r.get("params", {}).get(name), r.get("metrics", {}).get(metric)
        if is_real(x) and is_real(y) and math.isfinite(y):
            pts.append((float(x), float(y)))
    if len(pts) < 2:
        return f"{name}: fewer than 2 finite {metric} values"
    (x0, y0), (x1, y1) = min(pts), max(pts)
    return f"{name}: {metric} {y0:.4g} at {x0:g} -> {y1:.4g} at {x1:g}"


def run_sweep(study: str | os.PathLike | dict | Study, out: str | os.PathLike | None = None,
              workers: int | None = None, scheduler: str | None = None, progress: bool = True,
              case_fn: Callable[[dict], dict] = run_case,
              on_row: Callable[[dict], None] | None = None, max_cases: int | None = None,
              executor: str = "processes", overrides: Sequence[str] = (),
              case_timeout: float | None = None, allow_code: bool | None = None) -> SweepResult:
    """Run (or resume) a study; every case is built and validated before anything runs.

    workers: cases run at once (default all cores; ignored with a Dask `scheduler` address); executor:
    "processes" or "threads" (`executor.pick_executor`; the same results); case_fn: the worker function
    (top-level, picklable); on_row(row): called in the parent after each row is on disk; max_cases:
    replaces the study's [sampling] max_cases; overrides: 'key=value' (as `teleop run --set`) on the base
    scenario after the study's set, before the factors (part of study.toml and the case ids);
    case_timeout: seconds a case may take in its worker, set-up included (over it: a row with status
    "error").  Raises ConfigError for a bad study, an unreachable scheduler (before any file is written),
    an unusable output folder or a link at results.jsonl; SweepInterrupted on Ctrl-C/SIGTERM.  Output
    failures after the cases ran (recordings, summary) are listed in `SweepResult.failures`."""
    clock = [time.perf_counter()]  # SweepResult.timings: each lap adds the time since the last one

    def lap(phase: str) -> None:
        now = time.perf_counter()
        result.timings[phase] = result.timings.get(phase, 0.0) + now - clock[0]
        clock[0] = now

    if max_cases is not None:
        max_cases = check_max_cases(max_cases, "--max-cases")
    if not isinstance(study, Study):
        study = load_study(study, max_cases=max_cases, allow_code=allow_code)
    if max_cases is not None:
        study = dataclasses.replace(study, max_cases=max_cases)
    check_study_name(study.name)
    if overrides:
        if isinstance(overrides, str) or not all(isinstance(o, str) for o in overrides):
            raise ConfigError(f"overrides = {overrides!r}: must be a list of 'key=value' strings",
                              path="--set")
        study = dataclasses.replace(study, set=(*study.set, *overrides))
    case_timeout = check_case_timeout(case_timeout)
    check_case_count(study)
    base = load_base(study)
    cases = expand_cases(study, base)
    hidden = hidden_factors(study, cases)
    if hidden:
        log.warning(hidden_warning(hidden))
    runner = Runner(workers, scheduler, pick_executor(executor, scheduler, cases))
    runner.connect()  # a bad or unreachable scheduler is input: found before anything is written
    where = "--out" if out is not None else "sweep output folder (default)"
    out = prepare_out_dir(Path(out) if out is not None else DEFAULT_OUT_ROOT / study.name, where)
    lock = OutputLock(out)
    in_main = threading.current_thread() is threading.main_thread()
    old_term = signal.signal(signal.SIGTERM, _raise_interrupt) if in_main else None
    writer = bar = None
    try:
        header = (f"# Resolved study {study.name!r}, written by harness.studies.sweep "
                  "(re-runnable as a study file).\n")
        write_atomic(out / "study.toml", (header + tomli_w.dumps(_study_document(study, base))).encode())
        table = out / RESULTS
        refuse_link(table)
        known = read_results(table)
        todo = [c for c in cases if c.case_id not in known]
        done = {c.case_id: known[c.case_id] for c in cases if c.case_id in known}
        result = SweepResult(study, out, cases, done, skipped=len(cases) - len(todo), executor=runner.kind,
                             hidden=hidden)
        extra = len(set(known) - {c.case_id for c in cases})
        log.info("study %s: %d cases, %d already done, %d to run on %d %s%s", study.name, len(cases),
                 result.skipped, len(todo), runner.workers, runner.kind,
                 f" ({extra} rows of other cases in the table)" if extra else "")
        writer = ResultsWriter(table)
        bar = progress_bar_class()(total=len(cases), initial=result.skipped, desc=study.name, unit="case",
                                   disable=not progress or not todo, file=sys.stderr)

        def on_result(case: Case, res: dict) -> None:
            row = make_row(case, res)
            if row["status"] == "interrupted":  # the case did not finish: not a result, re-run it later
                result.unfinished += 1
                return
            try:
                writer.append(row)
            except OSError as e:  # e.g. a full disk: stop, the rows on disk are kept, a re-run resumes
                raise SweepError(f"cannot append to {table}: {describe_os_error(e)}; "
                                 f"{len(result.rows)} rows kept, re-run to resume") from None
            result.rows[case.case_id] = row
            result.ran += 1
            bar.update(1)
            if bad := sum(r["status"] != "ok" for r in result.rows.values()):
                bar.set_postfix_str(f"{bad} not ok", refresh=False)
            if on_row is not None:
                on_row(row)

        try:
            lap("setup")
            run_cases(runner, case_fn, todo, study.metrics, False, on_result, time_limit=case_timeout)
            bar.close()
            lap("cases")
            if study.record and result.complete:
                try:
                    result.recordings = _record_worst(study, result, runner, case_fn, case_timeout)
                except OutputError as e:  # the summary is still written
                    result.failures.append(str(e))
            runner.close()
            lap("recordings")
            try:
                result.summary = write_summary(study, cases, result.rows, out)
            except OutputError as e:
                result.failures.append(str(e))
            lap("summary")
        except KeyboardInterrupt:
            runner.close(cancel=True)
            raise SweepInterrupted(result) from None
    finally:
        if bar is not None:
            bar.close()
        runner.close(cancel=True)  # no-op after a normal end; else stop the workers now
        if writer is not None:
            writer.close()
        if in_main:
            signal.signal(signal.SIGTERM, old_term)
        lock.release()
    return result


def _record_worst(study: Study, result: SweepResult, runner: Runner, case_fn: Callable,
                  case_timeout: float | None = None) -> list[Path]:
    """Recordings of the study's worst cases (record = {worst, by, order}) not yet in recordings/."""
    folder = result.out / "recordings"
    if folder.is_symlink():
        raise OutputError(f"{folder}: is a symbolic link; recordings are not written through a link",
                          path=str(folder))
    try:
        folder.mkdir(exist_ok=True)
    except OSError as e:
        raise OutputError(f"cannot create {folder}: {describe_os_error(e)}", path=str(folder)) from None
    spec, rows = study.record, result.rows

    def value(case):
        v = rows[case.case_id]["metrics"].get(spec.by)
        return v if is_real(v) and rows[case.case_id]["status"] in ("ok", "diverged") else None

    worst = sorted((c for c in result.cases if value(c) is not None), key=value,
                   reverse=spec.order == "max")[: spec.worst]
    todo = [c for c in worst if not (folder / f"{c.case_id}.rrd").exists()]
    written = [folder / f"{c.case_id}.rrd" for c in worst if c not in todo]

    def on_result(case: Case, res: dict) -> None:
        data = res.get("recording")
        if not isinstance(data, bytes | bytearray):
            log.warning("recording of case %s failed: %s", case.case_id, res.get("message", "no data"))
            return
        written.append(write_atomic(folder / f"{case.case_id}.rrd", bytes(data)))

    if todo:
        log.info("recording the %d worst case(s) by %s", len(todo), study.record.by)
        run_cases(runner, case_fn, todo, study.metrics, True, on_result, time_limit=case_timeout)
    return written


EXIT_INTERRUPTED = 130  # as `teleop run` (harness.cli)


def main_sweep(study_path: str | os.PathLike, out: str | os.PathLike | None = None,
               workers: int | None = None, scheduler: str | None = None, progress: bool = True,
               max_cases: int | None = None, executor: str = "processes", overrides: Sequence[str] = (),
               case_timeout: float | None = None, allow_code: bool = False) -> int:
    """`teleop sweep`: 0 when every case has a row (diverged/error cases are data) and every output was
    written; 1 when cases are unfinished, the executor failed or an output (recordings, summary) could not
    be written; 130 when interrupted (re-run to resume).  A bad study or output folder raises ConfigError."""
    try:
        res = run_sweep(study_path, out=out, workers=workers, scheduler=scheduler, progress=progress,
                        max_cases=max_cases, executor=executor, overrides=overrides,
                        case_timeout=case_timeout, allow_code=allow_code)
    except SweepError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except SweepInterrupted as e:
        r = e.result
        print(f"interrupted: {len(r.rows)} of {len(r.cases)} cases done, kept in {r.out / RESULTS}; "
              "run the same command again to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    counts = ", ".join(f"{n} {s}" for s, n in sorted(res.counts().items()))
    t = res.timings
    rec = f"recordings {t['recordings']:.1f} s, " if res.recordings else ""
    rate = (f" in {t['cases']:.1f} s ({60.0 * res.ran / t['cases']:.0f} cases/min; set-up "
            f"{t['setup']:.1f} s, {rec}summary {t['summary']:.1f} s)" if res.ran and t.get("cases") else "")
    lines = [f"study {res.study.name}: {len(res.cases)} cases ({counts}); ran {res.ran} ({res.executor})"
             f"{rate}, {res.skipped} already done -> {res.out}", *(f"recording: {p}" for p in res.recordings)]
    if res.hidden:
        lines.append(f"{hidden_warning(res.hidden)} (measured: "
                     f"{'; '.join(sensitivity(res, n) for n in res.hidden)})")
    lines += [f"error: {f}" for f in res.failures]
    if not res.complete:
        lines.append(f"{res.unfinished} case(s) did not finish; run again to resume")
    print("\n".join(lines), file=sys.stderr)
    return 1 if res.failures or not res.complete else 0
