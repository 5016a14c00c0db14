"""Run an output writer in a forked child the parent can always stop (docs: Outputs and their guarantees):
its error is one `OutputError` line; a Rerun write error on its stderr, a stalled temporary file or Ctrl-C
kill it and remove its temporary files.  Without `fork` the writer runs in-process."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from harness.config.textio import TMP_MARK, OutputError, describe_os_error

STALL_TIMEOUT = 30.0  # s without growth of the temporary file before the writer is declared stuck
_POLL = 0.05  # s


def _child(fn: Callable[[], Any], conn, err_fd: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group: the parent decides
    os.dup2(err_fd, 2)  # native log lines (Rerun's sink errors) go to the parent, which keeps the cause
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


def _drain(fd: int, out: list[bytes]) -> None:
    with os.fdopen(fd, "rb", buffering=0) as fh:
        while chunk := fh.read(65536):
            if sum(map(len, out)) < 1 << 20:
                out.append(chunk)


def _native_cause(text: bytes) -> str:
    """The cause at the end of the first native ERROR line, e.g. 'File too large (os error 27)'."""
    for line in text.decode("utf-8", "replace").splitlines():
        line = re.sub(r"\x1b\[[0-9;]*m", "", line)
        if "ERROR" in line and ("file_sink" in line or "Failed to write" in line):
            return line.rsplit(": ", 1)[-1].strip()
    return ""


def _temps(path: Path, pid: int) -> list[Path]:
    """The temporary files of `path` that the writer process `pid` left (`atomic_path` names)."""
    return [p for p in path.parent.glob(f".{path.name}{TMP_MARK}{pid}*") if p.is_file()]


class ChildWriter:
    """A writer running in a forked child (`start_in_child`): `wait()` returns its path or raises
    `OutputError` (one line naming the file); `kill()` stops it (idempotent)."""

    def __init__(self, fn: Callable[[], Any], path: Path, stall_timeout: float | None,
                 others: tuple[Path, ...] = ()):
        self.path = path
        self.others = others
        self.stall_timeout = stall_timeout
        self.proc = None
        ctx = multiprocessing.get_context("fork")
        self.recv, send = ctx.Pipe(duplex=False)
        err_r, err_w = os.pipe()
        proc = ctx.Process(target=_child, args=(fn, send, err_w), daemon=True)
        # Ctrl-C must not land between the fork and the caller's `wait` (the child would be orphaned):
        # while starting, SIGINT is only recorded, and handled by the previous handler afterwards.
        got: list[int] = []
        old = (signal.signal(signal.SIGINT, lambda signum, frame: got.append(signum))
               if threading.current_thread() is threading.main_thread() else None)
        self.stderr: list[bytes] = []
        try:
            try:
                proc.start()
                self.proc = proc
            finally:
                send.close()
                os.close(err_w)
                if self.proc is None:
                    os.close(err_r)
                    self.recv.close()
            self._drain = threading.Thread(target=_drain, args=(err_r, self.stderr), daemon=True)
            self._drain.start()
            # restored inside the try: a Ctrl-C from here on still kills the child below
            if old is not None:
                signal.signal(signal.SIGINT, old)
            if got:
                if callable(old):
                    old(signal.SIGINT, None)  # default: raises KeyboardInterrupt
                elif old != signal.SIG_IGN:
                    raise KeyboardInterrupt
        except BaseException:
            if old is not None and signal.getsignal(signal.SIGINT) is not old:
                signal.signal(signal.SIGINT, old)
            self.kill()
            raise

    def wait(self) -> Path:
        path, proc, pid = self.path, self.proc, self.proc.pid
        last_size, last_change = -1, time.monotonic()
        try:
            while proc.is_alive():
                proc.join(_POLL)
                cause = _native_cause(b"".join(self.stderr))
                if cause:  # the file sink logged a write error: the data cannot complete, stop now
                    raise OutputError(f"cannot write {path}: the Rerun file sink failed ({cause})",
                                      path=str(path))
                if self.stall_timeout is None:
                    continue
                size = 0
                for tmp in _temps(path, pid):
                    with contextlib.suppress(OSError):  # renamed or removed meanwhile
                        size += tmp.stat().st_size
                now = time.monotonic()
                if size != last_size:
                    last_size, last_change = size, now
                elif now - last_change > self.stall_timeout:
                    raise OutputError(f"cannot write {path}: the writer made no progress for "
                                      f"{self.stall_timeout:g} s (stalled; file system full or blocked?)",
                                      path=str(path))
            status, msg = self.recv.recv() if self.recv.poll(1.0) else ("error", "")
            if proc.exitcode != 0 or status != "ok":
                self._drain.join(2.0)
                why = msg or f"the writer process ended with exit code {proc.exitcode}"
                cause = _native_cause(b"".join(self.stderr))
                if cause and cause not in why:
                    why += f" [{cause}]"
                raise OutputError(why if why.startswith("cannot write") else f"cannot write {path}: {why}",
                                  path=str(path))
            return path
        finally:
            self.kill()

    def kill(self) -> None:
        proc = self.proc
        if proc is None:
            return
        if proc.is_alive():
            proc.kill()
            proc.join(5.0)
        with contextlib.suppress(OSError):
            self.recv.close()
        # a killed or failed writer leaves temporary files (atomic_path names them with its pid)
        for target in (self.path, *self.others):
            for tmp in _temps(target, proc.pid):
                with contextlib.suppress(OSError):
                    tmp.unlink()


def start_in_child(fn: Callable[[], Any], path: str | Path, *, stall_timeout: float | None = STALL_TIMEOUT,
                   others: Sequence[str | Path] = ()) -> ChildWriter | SimpleNamespace:
    """Start `fn()` (which writes `path` through `atomic_path`) in a forked child and return at once.
    stall_timeout None: no progress check (writers that compute long before writing, e.g. figures).
    others: further files the writer writes atomically (their temporary files are removed if it fails)."""
    path = Path(path)
    try:
        multiprocessing.get_context("fork")
    except ValueError:  # no fork (Windows): the writer runs here, wait() and kill() have nothing to do
        fn()
        return SimpleNamespace(wait=lambda: path, kill=lambda: None)
    return ChildWriter(fn, path, stall_timeout, tuple(Path(o) for o in others))

