"""Where the benchmarks write their results: `benchmarks/results/<script>.md`, one file per script,
REPLACED by each run (written to a temporary name and renamed, so a file is always a complete run).
Each file says when and on what machine it was measured; git keeps the earlier runs."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def write_result(script: str, text: str) -> Path:
    """Replace benchmarks/results/<script stem>.md with `text`; returns the path."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{Path(script).stem}.md"
    fd, tmp = tempfile.mkstemp(dir=RESULTS, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text.rstrip() + "\n")
    os.replace(tmp, path)
    print(f"wrote {path}")
    return path
