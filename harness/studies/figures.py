"""What the studies' reports share: `run_paper`, progress lines (`printer`), and their files (figures, CSV,
Markdown tables, text), each written atomically (`harness.config.textio.write_atomic`)."""

from __future__ import annotations

import csv
import sys
from collections.abc import Sequence
from pathlib import Path

from harness.config.textio import write_atomic


def run_paper(sets: Sequence[str]) -> tuple:
    """(trajectory, metrics) of the default (paper) scenario with `--set`-style overrides."""
    from harness.config.load import load_scenario
    from harness.loop import simulate
    from harness.loop.metrics import compute_metrics

    scn = load_scenario(None, list(sets))
    tr = simulate(scn)
    return tr, compute_metrics(tr, scn)


def printer(progress: bool):
    """say(msg): a line on stderr when `progress`, else nothing."""
    return (lambda msg: print(msg, file=sys.stderr, flush=True)) if progress else (lambda msg: None)


def save(path, data) -> Path:
    """`write_atomic(path, data)` (bytes, text or a writer of the temporary path), parents created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomic(path, data)


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Write a matplotlib figure with `save` (format from the suffix, PNG by default) and close it."""
    path = Path(path)
    try:
        return save(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:] or "png"))
    finally:
        if (plt := sys.modules.get("matplotlib.pyplot")) is not None:
            plt.close(fig)


def save_csv(path, rows, header: Sequence[str] | None = None) -> Path:
    """A CSV file: `header`, then one row per sequence of cells; without a header the rows are dicts and
    the first one's keys are the header."""
    if header is None:
        header, rows = list(rows[0]), [list(r.values()) for r in rows]

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(rows)

    return save(path, write)


def md_table(head: Sequence[str], rows, align: Sequence[str] | None = None) -> list[str]:
    """Lines of a Markdown table: header cells, rows of cell strings; align: one separator cell per column
    ("---:" right, the default; "---" left; ":---:" centred)."""
    sep = align or ["---:"] * len(head)
    return [f"| {' | '.join(head)} |", f"|{'|'.join(sep)}|", *(f"| {' | '.join(r)} |" for r in rows)]
