"""Surfaces under faults: viewing, sweeps, what a user sees, and files from others (one test per fault
case; the subprocess ones are in the slow tier)."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from harness.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _main_within(argv: list[str], timeout: float = 60.0) -> int:
    """`main(argv)` in a thread; fails (instead of hanging the suite) if it does not return in time."""
    result: list[int] = []
    th = threading.Thread(target=lambda: result.append(main(argv)), daemon=True)
    th.start()
    th.join(timeout)
    assert result, f"teleop {' '.join(argv)} did not return within {timeout} s"
    return result[0]


# ---------------------------------------------------------------------------------------------
# files from others: non-regular input files
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["scenario", "bounds", "study"])
def test_named_pipe_input_is_refused_in_one_line(tmp_path, capsys, kind):
    fifo = tmp_path / f"{kind}.toml"
    os.mkfifo(fifo)
    argv = {"scenario": ["run", str(fifo), "--out", str(tmp_path / "o"), "--no-progress"],
            "bounds": ["check", "--bounds", str(fifo), "--duration", "0.1", "--no-progress"],
            "study": ["sweep", str(fifo), "--out", str(tmp_path / "o"), "--no-progress"]}[kind]
    assert _main_within(argv, timeout=20.0 if kind != "bounds" else 120.0) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a regular file" in err[0] and str(fifo) in err[0], err


# ---------------------------------------------------------------------------------------------
# what a user sees: progress bars only on a terminal
# ---------------------------------------------------------------------------------------------
def test_progress_bar_not_drawn_when_stderr_is_not_a_terminal(tmp_path, capsys):
    assert main(["run", "--duration", "0.3", "--out", str(tmp_path / "o")]) == 0  # no --no-progress
    err = capsys.readouterr().err
    assert "step/s" not in err and "%|" not in err and "\r" not in err, err


def test_progress_bar_drawn_on_a_terminal():
    import io

    from harness.config.runtime import progress_bar_class

    class Tty(io.StringIO):
        def isatty(self):
            return True

    for stream, drawn in ((Tty(), True), (io.StringIO(), False)):
        with progress_bar_class()(total=3, file=stream, desc="x", mininterval=0) as bar:
            bar.update(3)
        assert ("3/3" in stream.getvalue()) == drawn
