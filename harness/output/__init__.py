"""Outputs of a run, consumers of an in-memory `Trajectory`: the Rerun recording (`record`), the figures
(`plots`) and the live viewer (`viewer`).  This package itself imports neither matplotlib nor Rerun."""

# what `harness.output.plots.write_figures` writes (forces.png only for runs with interaction)
FIGURES = ("fig2_e1.png", "fig3_e2.png", "fig4_beta.png", "q2.png", "shapes.png", "forces.png")
