"""Names of a run's output files, importable without matplotlib or Rerun (a run clears a reused
folder by these names before it simulates; `harness.output.plots` draws the figures)."""

from __future__ import annotations

# what `harness.output.plots.write_figures` writes (forces.png only for runs with interaction)
FIGURES = ("fig2_e1.png", "fig3_e2.png", "fig4_beta.png", "q2.png", "shapes.png", "forces.png")
