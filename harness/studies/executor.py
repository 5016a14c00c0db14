"""Executors of a sweep: the worker function (`run_case`), a process pool (recreated after a worker
died; a dying worker's case is isolated and blamed), threads of this process, or a Dask client, and the
loop that keeps cases in flight and hands each result to the parent as it finishes.

Threads (`--executor threads`, the in-process batch path): the compiled loops release the GIL while they
step (`harness.loop.releases_gil`), so the cases of one process run on every core without worker
processes, with the same results.  Processes stay the default: a crashing case then takes only its
worker (benchmarks/bench_core.py measures both).
"""


from __future__ import annotations

import atexit
import concurrent.futures as cf
import dataclasses
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


def _error_result(e: BaseException) -> dict:
    return {"status": "error", "message": f"{type(e).__name__}: {e}",
            "traceback": "".join(traceback.format_exception(e))}


class CaseTimeout(RuntimeError):
    """A case ran longer than the sweep's per-case time limit."""


def check_case_timeout(value) -> float | None:
    """The per-case time limit in seconds (None: no limit); ConfigError unless a positive finite number."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        raise ConfigError(f"--case-timeout = {value!r}: must be a positive number of seconds",
                          path="--case-timeout")
    return float(value)


def _deadline_check(t0: float, limit: float):
    """on_chunk callback raising CaseTimeout once `limit` seconds have passed since t0."""
    def check(part) -> None:
        if time.perf_counter() - t0 > limit:
            t = float(part.t[-1]) if len(part) else 0.0
            raise CaseTimeout(f"the case exceeded the time limit of {limit:g} s (--case-timeout) at "
                              f"t = {t:.3f} s of simulated time")
    return check


def run_case(case: dict) -> dict:
    """Worker: simulate one case and compute its metrics.  Never raises (an exception gives status
    "error" with the message and traceback); a diverged run keeps the Trajectory's status.

    case: {"case_id", "scenario": Scenario, "metrics": [names], "record": bool, "time_limit": s or None}.
    With a time limit the loop checks it after each chunk of steps (`CaseTimeout`: status "error"); a case
    that blocks inside a step is stopped by the parent (`run_cases`).
    Returns {"case_id", "status", "message", "metrics", "wall_time", "traceback"} (+ "recording":
    the .rrd bytes when case["record"])."""
    t0 = time.perf_counter()
    out = {"case_id": case.get("case_id"), "metrics": {}, "traceback": ""}
    try:
        from harness.loop import simulate
        from harness.loop.metrics import compute_metrics

        scn = case["scenario"]
        # a sweep keeps every core busy with cases: no second thread per case (it would spin-wait for a core)
        limit = case.get("time_limit")
        traj = simulate(scn, progress=False,
                        on_chunk=_deadline_check(t0, limit) if limit else None)
        metrics = compute_metrics(traj, scn)
        out.update(status=traj.status, message=traj.message,
                   metrics={k: jsonable(metrics.get(k)) for k in case["metrics"]})
        if case.get("record"):
            from harness.output.record import write_recording

            traj.meta["environment"] = [dataclasses.asdict(o) for o in scn.environment.objects]
            with tempfile.TemporaryDirectory(prefix="sweep-rec-") as tmp:
                path = Path(tmp) / f"{case.get('case_id')}.rrd"
                write_recording(traj, path)
                out["recording"] = path.read_bytes()
    except Exception as e:
        out.update(_error_result(e))
    out["wall_time"] = time.perf_counter() - t0
    return out


def _call(case_fn: Callable[[dict], dict], payload: dict) -> dict:
    """Runs in the worker: an exception raised by case_fn is the case's result, so that any exception
    a future raises in the parent comes from the executor itself."""
    try:
        return case_fn(payload)
    except Exception as e:
        return _error_result(e)


PARENT_POLL = 0.5  # s: how often a pool worker checks that the main process is still alive


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(PARENT_POLL)
        if os.getppid() != parent:  # re-parented: the main process died (kill -9, crash)
            os._exit(70)


def _worker_init() -> None:
    # Ctrl-C reaches the whole process group: only the parent reacts (it cancels and stops us).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a forked worker inherits the parent's SIGTERM handler (the sweep's clean stop): not ours
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    # registered last, so run first at exit: the worker ends without the interpreter's teardown (~0.7 s
    # with numba and MuJoCo loaded, which the pool's shutdown, i.e. the sweep, would wait for); every
    # result has been sent by then
    atexit.register(end_process, 0)
    set_gc_thresholds()  # fewer collections while the first case imports the loop and MuJoCo
    # A killed main process cannot stop its pool: the kernel kills each worker when its parent ends (Linux
    # parent-death signal; it works while a case blocks holding the GIL); elsewhere each worker ends
    # itself within PARENT_POLL s.
    die_with_parent(signal.SIGKILL)
    threading.Thread(target=_watch_parent, args=(os.getppid(),), name="parent-watchdog", daemon=True).start()


# --- execution --------------------------------------------------------------------------------------
class SweepError(RuntimeError):
    """The executor failed (not a case): the sweep stops; finished rows are kept, a re-run resumes."""


CONNECT_TIMEOUT = 5.0  # s: connecting to a Dask scheduler, and waiting for its first worker


EXECUTORS = ("processes", "threads")  # run_sweep(executor=...), teleop sweep --executor


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
    """An executor created on demand: a process pool (recreated after a worker died), a thread pool, or a
    Dask client (`kind`: "processes", "threads", "dask")."""

    def __init__(self, workers: int | None, scheduler: str | None, kind: str = "processes"):
        self.workers = max(1, workers or os.cpu_count() or 1)
        self.scheduler = scheduler
        self.kind = kind  # `pick_executor`: "dask" exactly when there is a scheduler
        self._ex: cf.Executor | None = None
        self._client = None

    @property
    def window(self) -> float:
        # Process pool: only `workers` cases in flight, so a dead worker implicates few cases.
        return math.inf if self.scheduler else self.workers

    def connect(self) -> None:
        """Connect to the Dask scheduler now and check it has a worker (ConfigError within about
        CONNECT_TIMEOUT s otherwise).  No-op for a process pool."""
        if self.scheduler and self._client is None:
            from distributed import Client

            where = f"--scheduler = {self.scheduler!r}"
            try:
                self._client = Client(self.scheduler, timeout=f"{CONNECT_TIMEOUT}s")
            except Exception as e:  # noqa: BLE001 - OSError/TimeoutError/ValueError/TypeError: all input
                why = " ".join(str(e).split())[:200]
                raise ConfigError(f"{where}: cannot connect to the Dask scheduler "
                                  f"(timeout {CONNECT_TIMEOUT:g} s; {type(e).__name__}: {why})",
                                  path="scheduler") from None
            try:
                self._client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
            except Exception:  # noqa: BLE001 - TimeoutError (type differs between versions)
                self._client.close()
                self._client = None
                raise ConfigError(f"{where}: the scheduler has no worker (none joined within "
                                  f"{CONNECT_TIMEOUT:g} s)", path="scheduler") from None

    def start(self) -> None:
        """Start the process pool's workers now (no-op for threads, Dask or a started pool): called by the
        sweep before it starts threads of its own (progress bar, imports), so that the workers can be forked
        (see `_process_pool`)."""
        if self.kind != "processes" or self._ex is not None:
            return
        ex = self.executor()
        for _ in range(self.workers):
            try:  # a fork pool forks every worker at its first submit; spawn: one per submit
                ex.submit(_probe)
            except cf.BrokenExecutor:  # a worker died already: run_cases replaces the pool
                return

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
            if isinstance(ex, cf.ProcessPoolExecutor):
                _stop_pool(ex, cancel)
            elif isinstance(ex, cf.ThreadPoolExecutor):
                _stop_threads(ex, cancel)
            else:
                ex.shutdown(wait=not cancel)
        if self._client is not None:
            self._client.close()
            self._client = None


# modules a case needs, imported by the parent before it forks its workers (they then start with them)
WARM_MODULES = ("harness.loop", "harness.loop.mujoco_loop", "harness.loop.analytic_loop",
                "harness.loop.metrics", "harness.plant")


def start_method() -> str:
    """How pool workers start: "fork" on Linux when this process runs no other Python thread (the
    workers inherit the imported harness, numpy and MuJoCo: no interpreter start-up, no imports, an
    estimated 0.8 s less per worker on the reference machine, not measured apart); else "spawn" (fresh
    interpreters: safe beside threads, and unlike "forkserver" they see the current environment)."""
    if sys.platform.startswith("linux") and threading.active_count() == 1:
        return "fork"
    return "spawn"


def _process_pool(workers: int) -> cf.ProcessPoolExecutor:
    method = start_method()
    if method == "fork":
        for name in WARM_MODULES:
            importlib.import_module(name)
        sys.stdout.flush()  # a forked worker flushes its copy of unwritten output when it ends
        sys.stderr.flush()
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                                  initializer=_worker_init)


def _stop_pool(ex: cf.ProcessPoolExecutor, cancel: bool) -> None:
    if not cancel:
        ex.shutdown(wait=True)
        return
    if hasattr(ex, "terminate_workers"):  # Python >= 3.14
        ex.terminate_workers()
        return
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:  # running cases are lost (they re-run on resume); don't wait for them
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=10)


def _stop_threads(ex: cf.ThreadPoolExecutor, cancel: bool) -> None:
    """Shut a thread pool down; cancel: the pending cases are dropped and the running ones stop at their
    next chunk of steps (`harness.loop.common.STOP`; they come back "interrupted" and re-run on resume).
    A thread cannot be killed: this waits for them (a compiled chunk lasts about 0.25 s, 250 steps of the
    Python-stepped loop about 0.05 s on the Cosserat rod)."""
    from harness.loop.common import STOP

    if not cancel:
        ex.shutdown(wait=True)
        return
    STOP.set()
    try:
        ex.shutdown(wait=True, cancel_futures=True)
    finally:
        STOP.clear()


def _payload(case: Case, metrics: Sequence[str], record: bool, time_limit: float | None = None) -> dict:
    return {"case_id": case.case_id, "scenario": case.scenario, "metrics": list(metrics), "record": record,
            "time_limit": time_limit}


HARD_LIMIT_GRACE = 10.0  # s past the per-case time limit before the parent stops a worker that blocks


def _timeout_result(limit: float) -> dict:
    return {"status": "error", "traceback": "", "message":
            f"the case exceeded the time limit of {limit:g} s (--case-timeout) and did not return; its "
            f"worker was stopped {HARD_LIMIT_GRACE:g} s later"}


def run_cases(runner: Runner, case_fn: Callable, cases: Sequence[Case], metrics: Sequence[str],
               record: bool, on_result: Callable[[Case, dict], None],
               time_limit: float | None = None) -> None:
    """Run cases through the runner, calling on_result(case, result) in the parent as each finishes.
    An exception raised by case_fn counts as the case's result (status "error"); a dead process pool
    re-runs the cases that were in flight one by one to find the one that kills its worker.

    time_limit: seconds per case.  The worker stops a case over it at its next chunk of steps; on the
    process pool, a case still running HARD_LIMIT_GRACE s later (blocked inside a step) gets an error row,
    the pool's workers are stopped and the other cases in flight run again."""
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
                    fut = ex.submit(_call, case_fn, _payload(case, metrics, record, time_limit))
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
            if not done and hard is not None:  # a case blocks past its limit: stop the pool
                now = time.monotonic()
                late = [f for f in inflight if now - started[f] >= hard]
                if not late:  # woke up a little early
                    continue
                runner.close(cancel=True)
                for fut in list(inflight):
                    case = inflight.pop(fut)
                    if fut in late:
                        on_result(case, _timeout_result(time_limit))
                    else:
                        queue.appendleft(case)  # innocent: runs again in the fresh pool
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
                    on_result(case, _isolated(case_fn, _payload(case, metrics, record, time_limit),
                                              hard))
    finally:
        for fut in inflight:
            fut.cancel()


def _probe() -> int:
    return os.getpid()


def _isolated(case_fn: Callable, payload: dict, hard: float | None = None) -> dict:
    """Run one case alone in a fresh 1-process pool whose worker has first run a no-op, so that a
    dead worker is this case's doing (else: SweepError, e.g. workers that cannot start).  hard: seconds
    after which a case that has not returned is an error row (its worker is stopped)."""
    ex = _process_pool(1)
    try:
        try:
            ex.submit(_probe).result()
        except cf.BrokenExecutor:
            raise SweepError(
                "worker processes die before running any case (if run_sweep is called from a script, "
                "guard the call with `if __name__ == '__main__':`)") from None
        return ex.submit(_call, case_fn, payload).result(timeout=hard)
    except cf.TimeoutError:
        return _timeout_result(payload["time_limit"])
    except cf.BrokenExecutor:
        return {"status": "error", "traceback": "", "message":
                "the worker process died while running this case (segfault, abort or out of memory)"}
    finally:
        _stop_pool(ex, cancel=True)


