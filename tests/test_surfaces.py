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
