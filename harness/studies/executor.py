"""Executors of a sweep: the worker (`run_case`); a process pool (a crashing case is isolated and blamed),
threads (the compiled loops release the GIL) or a Dask client; `run_cases` keeps cases in flight and hands
each result to the parent as it finishes."""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import importlib
import logging
import math
import multiprocessing
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path

from harness.config.errors import ConfigError
from harness.config.runtime import die_with_parent, end_process, set_gc_thresholds
from harness.config.textio import jsonable
from harness.studies.study import Case

log = logging.getLogger(__name__)

EXECUTORS = ("processes", "threads")  # run_sweep(executor=...), teleop sweep --executor
CONNECT_TIMEOUT = 5.0  # s: connecting to a Dask scheduler, and waiting for its first worker
PARENT_POLL = 0.5  # s: how often a pool worker checks that the main process is still alive
HARD_LIMIT_GRACE = 10.0  # s past the per-case time limit before the parent stops a worker that blocks
# modules a case needs, imported by the parent before it forks its workers (they then start with them)
WARM_MODULES = ("harness.loop", "harness.loop.mujoco_loop", "harness.loop.analytic_loop",
                "harness.loop.metrics", "harness.plant")


class SweepError(RuntimeError):
    """The executor failed (not a case): the sweep stops; finished rows are kept, a re-run resumes."""


class CaseTimeout(RuntimeError):
    """A case ran longer than the sweep's per-case time limit."""


def _error_result(e: BaseException | None = None, message: str = "") -> dict:
    if e is not None:
        message = f"{type(e).__name__}: {e}"
    return {"status": "error", "message": message,
            "traceback": "".join(traceback.format_exception(e)) if e is not None else ""}


def _timeout_result(limit: float) -> dict:
    return _error_result(message=f"the case exceeded the time limit of {limit:g} s (--case-timeout) and did "
                         f"not return; its worker was stopped {HARD_LIMIT_GRACE:g} s later")


def check_case_timeout(value) -> float | None:
    """The per-case time limit in seconds (None: no limit); ConfigError unless a positive finite number."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        raise ConfigError(f"--case-timeout = {value!r}: must be a positive number of seconds",
                          path="--case-timeout")
    return float(value)


def run_case(case: dict) -> dict:
    """Worker: simulate one case and compute its metrics; never raises (an exception gives status "error").
    case: {"case_id", "scenario", "metrics": [names], "record": bool, "time_limit": s or None (`CaseTimeout`
    at the next chunk of steps)}.  Returns {"case_id", "status", "message", "metrics", "wall_time",
    "traceback"} (+ "recording": the .rrd bytes if "record")."""
    t0 = time.perf_counter()
    out = {"case_id": case.get("case_id"), "metrics": {}, "traceback": ""}
    limit = case.get("time_limit")

    def deadline(part) -> None:
        if time.perf_counter() - t0 > limit:
            t = float(part.t[-1]) if len(part) else 0.0
            raise CaseTimeout(f"the case exceeded the time limit of {limit:g} s (--case-timeout) at "
                              f"t = {t:.3f} s of simulated time")

    try:
        from harness.loop import simulate
        from harness.loop.metrics import compute_metrics

        scn = case["scenario"]
        traj = simulate(scn, progress=False, on_chunk=deadline if limit else None)
        metrics = compute_metrics(traj, scn)
        out.update(status=traj.status, message=traj.message,
                   metrics={k: jsonable(metrics.get(k)) for k in case["metrics"]})
        if case.get("record"):
            from harness.output.record import write_recording

            with tempfile.TemporaryDirectory(prefix="sweep-rec-") as tmp:
                path = Path(tmp) / f"{case.get('case_id')}.rrd"
                write_recording(traj, path)
                out["recording"] = path.read_bytes()
    except Exception as e:
        out.update(_error_result(e))
    out["wall_time"] = time.perf_counter() - t0
    return out


def _call(case_fn: Callable[[dict], dict], payload: dict) -> dict:
    """In the worker: an exception of case_fn is the case's result, so that an exception a future raises
    in the parent comes from the executor itself."""
    try:
        return case_fn(payload)
    except Exception as e:
        return _error_result(e)


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(PARENT_POLL)
        if os.getppid() != parent:  # re-parented: the main process died (kill -9, crash)
            os._exit(70)


def _worker_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group: the parent reacts
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's clean-stop handler (inherited by fork)
    # run first at exit: no interpreter teardown (~0.7 s) for the pool's shutdown to wait for
    atexit.register(end_process, 0)
    set_gc_thresholds()
    # a killed main process cannot stop its pool: Linux kills each worker with it, else the watchdog
    die_with_parent(signal.SIGKILL)
    threading.Thread(target=_watch_parent, args=(os.getppid(),), name="parent-watchdog", daemon=True).start()


def start_method() -> str:
    """How pool workers start: "fork" on Linux when this process runs no other Python thread (the workers
    inherit the imported modules), else "spawn"."""
    return "fork" if sys.platform.startswith("linux") and threading.active_count() == 1 else "spawn"


def _process_pool(workers: int) -> cf.ProcessPoolExecutor:
    method = start_method()
    if method == "fork":
        for name in WARM_MODULES:
            importlib.import_module(name)
        sys.stdout.flush()  # a forked worker flushes its copy of unwritten output when it ends
        sys.stderr.flush()
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                                  initializer=_worker_init)


def _stop(ex: cf.Executor, cancel: bool) -> None:
    """Shut an executor down; cancel: drop the pending cases and stop the running ones (workers terminated;
    threads stop at their next chunk, `harness.loop.common.STOP`, "interrupted": both re-run on resume)."""
    if not cancel or not isinstance(ex, cf.ProcessPoolExecutor | cf.ThreadPoolExecutor):
        ex.shutdown(wait=not cancel)
    elif isinstance(ex, cf.ThreadPoolExecutor):
        from harness.loop.common import STOP

        STOP.set()
        try:  # a thread cannot be killed: wait for them (a compiled chunk lasts about 0.25 s)
            ex.shutdown(wait=True, cancel_futures=True)
        finally:
            STOP.clear()
    elif hasattr(ex, "terminate_workers"):  # Python >= 3.14
        ex.terminate_workers()
    else:
        procs = list((getattr(ex, "_processes", None) or {}).values())
        ex.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(timeout=10)


def pick_executor(executor: str, scheduler: str | None, cases: Sequence[Case]) -> str:
    """The executor a sweep uses ("dask" with a scheduler, else `executor`): ConfigError for an unknown
    name, or threads with a scheduler.  Threads on cases that hold the GIL (Python-stepped plants or
    controllers, `harness.loop.releases_gil`) run one at a time: a warning says so."""
    if executor not in EXECUTORS:
        raise ConfigError(f"--executor = {executor!r}: must be one of {', '.join(EXECUTORS)}",
                          path="executor")
    if scheduler:
        if executor == "threads":
            raise ConfigError("--executor = 'threads' runs the cases in this process; it cannot be combined "
                              f"with --scheduler = {scheduler!r} (a Dask cluster)", path="executor")
        return "dask"
    if executor == "threads":
        from harness.loop import releases_gil

        held = sum(not releases_gil(c.scenario) for c in cases)
        if held:
            log.warning("--executor threads: %d of %d cases run a Python-stepped plant or controller, which "
                        "holds the GIL: those run one at a time (use processes)", held, len(cases))
    return executor


class Runner:
    """An executor created on demand (`kind`: "processes", a pool recreated after a worker died;
    "threads"; "dask", a client of `scheduler`) running `workers` cases at once (Dask: all)."""

    def __init__(self, workers: int | None, scheduler: str | None, kind: str = "processes"):
        self.workers = max(1, workers or os.cpu_count() or 1)
        self.scheduler = scheduler
        self.kind = kind
        self.window = math.inf if scheduler else self.workers  # cases in flight
        self._ex: cf.Executor | None = None
        self._client = None

    def connect(self) -> None:
        """Connect to the Dask scheduler now and check it has a worker (ConfigError within about
        CONNECT_TIMEOUT s otherwise).  No-op without a scheduler."""
        if not self.scheduler or self._client is not None:
            return
        from distributed import Client

        where = f"--scheduler = {self.scheduler!r}"
        try:
            self._client = Client(self.scheduler, timeout=f"{CONNECT_TIMEOUT}s")
        except Exception as e:  # noqa: BLE001 - OSError/TimeoutError/ValueError/TypeError: all input
            why = " ".join(str(e).split())[:200]
            raise ConfigError(f"{where}: cannot connect to the Dask scheduler (timeout {CONNECT_TIMEOUT:g} "
                              f"s; {type(e).__name__}: {why})", path="scheduler") from None
        try:
            self._client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
        except Exception:  # noqa: BLE001 - TimeoutError (type differs between versions)
            self.close()
            raise ConfigError(f"{where}: the scheduler has no worker (none joined within "
                              f"{CONNECT_TIMEOUT:g} s)", path="scheduler") from None

    def executor(self) -> cf.Executor:
        if self._ex is None:
            if self.scheduler:
                self.connect()
                self._ex = self._client.get_executor(pure=False)
            elif self.kind == "threads":
                self._ex = cf.ThreadPoolExecutor(self.workers, thread_name_prefix="sweep-case")
            else:
                self._ex = _process_pool(self.workers)
        return self._ex

    def close(self, cancel: bool = False) -> None:
        ex, self._ex = self._ex, None
        if ex is not None:
            _stop(ex, cancel)
        if self._client is not None:
            self._client.close()
            self._client = None


def run_cases(runner: Runner, case_fn: Callable, cases: Sequence[Case], metrics: Sequence[str],
              record: bool, on_result: Callable[[Case, dict], None], time_limit: float | None = None) -> None:
    """Run cases, calling on_result(case, result) in the parent as each finishes (an exception of case_fn:
    status "error").  A dead process pool re-runs the cases in flight one by one to blame one.  time_limit:
    s per case; on the pool a case still running HARD_LIMIT_GRACE s past it gets an error row and the
    workers are stopped (the other cases in flight run again)."""
    def payload(case: Case) -> dict:
        return {"case_id": case.case_id, "scenario": case.scenario, "metrics": list(metrics),
                "record": record, "time_limit": time_limit}

    queue = deque(cases)
    inflight: dict[cf.Future, Case] = {}
    started: dict[cf.Future, float] = {}
    hard = time_limit + HARD_LIMIT_GRACE if time_limit and runner.kind == "processes" else None
    try:
        while queue or inflight:
            ex = runner.executor()
            while queue and len(inflight) < runner.window:
                case = queue.popleft()
                try:
                    fut = ex.submit(_call, case_fn, payload(case))
                except cf.BrokenExecutor:  # a worker died since the last wait: its futures say which
                    queue.appendleft(case)
                    break
                inflight[fut] = case
                started[fut] = time.monotonic()
            if not inflight:  # broken before anything was in flight: nothing to blame, a fresh pool
                runner.close(cancel=True)
                continue
            wait = None if hard is None else max(0.1, min(started.values()) + hard - time.monotonic())
            done, _ = cf.wait(inflight, timeout=wait, return_when=cf.FIRST_COMPLETED)
            if not done and hard is not None:  # a case blocks past its limit (or: woke up a little early)
                late = [f for f in inflight if time.monotonic() - started[f] >= hard]
                if late:
                    runner.close(cancel=True)
                    for fut in list(inflight):
                        if fut in late:
                            on_result(inflight.pop(fut), _timeout_result(time_limit))
                        else:  # innocent: runs again in the fresh pool
                            queue.appendleft(inflight.pop(fut))
                    started.clear()
                continue
            if any(not f.cancelled() and isinstance(f.exception(), cf.BrokenExecutor) for f in done):
                cf.wait(inflight)  # a broken pool fails every future at once
                done = set(inflight)
            suspects = []
            for fut in done:
                case = inflight.pop(fut)
                started.pop(fut, None)
                if fut.cancelled():
                    raise RuntimeError(f"case {case.case_id} was cancelled by the executor "
                                       "(scheduler or workers lost?); run again to resume")
                exc = fut.exception()
                if exc is None:
                    on_result(case, fut.result())
                elif isinstance(exc, cf.BrokenExecutor):
                    suspects.append(case)
                elif type(exc).__name__ == "KilledWorker":  # Dask: this case killed its workers
                    on_result(case, _error_result(exc))
                else:
                    raise SweepError(f"the executor failed on case {case.case_id}: "
                                     f"{type(exc).__name__}: {exc}; re-run to resume") from exc
            if suspects:
                log.warning("a worker process died; re-running %d case(s) one at a time", len(suspects))
                runner.close(cancel=True)
                for case in suspects:
                    on_result(case, _isolated(case_fn, payload(case), hard))
    finally:
        for fut in inflight:
            fut.cancel()


def _isolated(case_fn: Callable, payload: dict, hard: float | None = None) -> dict:
    """Run one case alone in a fresh 1-process pool after a no-op (SweepError if that fails), so that a dead
    worker is this case's doing.  hard: s after which the case is an error row."""
    ex = _process_pool(1)
    try:
        try:
            ex.submit(os.getpid).result()  # a no-op
        except cf.BrokenExecutor:
            raise SweepError(
                "worker processes die before running any case (if run_sweep is called from a script, "
                "guard the call with `if __name__ == '__main__':`)") from None
        return ex.submit(_call, case_fn, payload).result(timeout=hard)
    except cf.TimeoutError:
        return _timeout_result(payload["time_limit"])
    except cf.BrokenExecutor:
        return _error_result(message="the worker process died while running this case (segfault, abort or "
                             "out of memory)")
    finally:
        _stop(ex, cancel=True)
