"""Run an output writer in a child process that the parent can always stop.

Why: the Rerun file sink writes from a thread of its own; when a write fails (full disk, `ulimit -f`)
the failure only shows when the stream is flushed, and a writer blocked inside native code cannot be
interrupted by Ctrl-C (Python delivers KeyboardInterrupt only between bytecodes of the main thread).
`write_in_child` forks a child that runs the writer (which writes to a temporary name and renames it
into place only when complete, see `harness.config.textio.atomic_path`); the parent waits in short
polls, so that

* an error in the child comes back as one line (`OutputError` naming the file and the cause);
* a child that stops making progress (its temporary file has not grown for `stall_timeout` s) is
  killed and reported, never a hang;
* Ctrl-C (KeyboardInterrupt in the parent) kills the child, removes its temporary file and
  re-raises, so a run always ends.

Platforms without `fork` run the writer in-process (same atomic rename, no stall detection).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from harness.config.textio import TMP_MARK, OutputError, describe_os_error

STALL_TIMEOUT = 30.0  # s without growth of the temporary file before the writer is declared stuck
_POLL = 0.05  # s


def _child(fn: Callable[[], Any], conn) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group: the parent decides
    try:
        fn()
        conn.send(("ok", ""))
        code = 0
    except BaseException as e:  # noqa: BLE001 - reported to the parent as one line
        msg = str(e) if isinstance(e, OutputError) else describe_os_error(e)
        with contextlib.suppress(Exception):
            conn.send(("error", " ".join(msg.split())))
        code = 1
    conn.close()
    os._exit(code)  # no atexit handlers (the Rerun SDK's shutdown belongs to the parent)


def _temps(path: Path, pid: int | None) -> list[Path]:
    pat = f".{path.name}{TMP_MARK}{pid if pid is not None else ''}*"
    return [p for p in path.parent.glob(pat) if p.is_file()]


def _size(paths: list[Path]) -> int:
    total = 0
    for p in paths:
        with contextlib.suppress(OSError):
            total += p.stat().st_size
    return total


def write_in_child(fn: Callable[[], Any], path: str | Path, *, stall_timeout: float = STALL_TIMEOUT) -> Path:
    """Run `fn()` (which writes `path` through `atomic_path`) in a forked child and wait for it.

    Returns `path`.  Raises `OutputError` (one line naming `path`) if the child fails, dies or stalls
    for `stall_timeout` s; KeyboardInterrupt kills the child first.  Never leaves a temporary file."""
    path = Path(path)
    try:
        ctx = multiprocessing.get_context("fork")
    except ValueError:  # no fork (Windows): in-process
        fn()
        return path
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(fn, send), daemon=True)
    proc.start()
    send.close()
    pid = proc.pid
    last_size, last_change = -1, time.monotonic()
    try:
        while proc.is_alive():
            proc.join(_POLL)
            size = _size(_temps(path, pid))
            now = time.monotonic()
            if size != last_size:
                last_size, last_change = size, now
            elif now - last_change > stall_timeout:
                raise OutputError(f"cannot write {path}: the writer made no progress for {stall_timeout:g} s "
                                  "(stalled; file system full or blocked?)", path=str(path))
        status, msg = recv.recv() if recv.poll(1.0) else ("error", "")
        if proc.exitcode != 0 or status != "ok":
            why = msg or f"the writer process ended with exit code {proc.exitcode}"
            raise OutputError(why if why.startswith("cannot write") else f"cannot write {path}: {why}",
                              path=str(path))
        return path
    finally:
        if proc.is_alive():
            proc.kill()
            proc.join(5.0)
        recv.close()
        for p in _temps(path, pid):
            with contextlib.suppress(OSError):
                p.unlink()


__all__ = ["STALL_TIMEOUT", "write_in_child"]
