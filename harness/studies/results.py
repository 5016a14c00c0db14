"""A sweep's append-only `results.jsonl` (one fsynced line per case), its reader (a torn tail ignored) and
the folder lock; nothing is read or written through a symbolic link."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from harness.config.errors import ConfigError
from harness.config.textio import jsonable
from harness.studies.study import Case

log = logging.getLogger(__name__)

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
