"""How the studies' figures are written: `save_figure`, the one path for every study figure (the run's own
figures: `harness.output.plots`)."""

from __future__ import annotations

from pathlib import Path

from harness.config.textio import write_atomic


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Write a pyplot figure to `path` (parent folders created; the format from the suffix, PNG by
    default) under a temporary name renamed into place when complete (`write_atomic`: a file under its
    final name is whole), close it and return the path."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        return write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:] or "png"))
    finally:
        plt.close(fig)
