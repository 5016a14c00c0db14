"""PNG figures (paper Figs. 2-4, q2, shapes)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from matplotlib.image import imread

from harness.output.plots import write_figures

NAMES = ["fig2_e1.png", "fig3_e2.png", "fig4_beta.png", "q2.png", "shapes.png"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _check_pngs(paths, outdir):
    assert [p.name for p in paths] == NAMES
    for p in paths:
        assert p.parent == outdir and p.is_file()
        assert p.read_bytes()[:8] == PNG_MAGIC, p
        img = imread(p)
        assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 300, (p, img.shape)
        assert np.ptp(img[..., :3]) > 0.5, f"{p.name} is blank"  # something was drawn


def test_full_run_figures(tmp_path, synthetic_trajectory):
    outdir = tmp_path / "figs"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no matplotlib/numpy warnings on a normal run
        paths = write_figures(synthetic_trajectory(1200), outdir)
    _check_pngs(paths, outdir)


@pytest.mark.parametrize("n", [37, 2, 1])
def test_early_stopped_and_tiny_runs(tmp_path, synthetic_trajectory, n):
    traj = synthetic_trajectory(n, status="diverged", message="NaN in qacc", nan_tail=min(4, n - 1))
    _check_pngs(write_figures(traj, tmp_path), tmp_path)


def test_analytic_plant_without_meta(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(300, plant=False, with_master_pos=False)
    traj.meta = {}  # no geometry, bases or ranges: defaults must still draw
    _check_pngs(write_figures(traj, tmp_path, lengths=(0.6, 0.6)), tmp_path)


def test_broken_backbone_fn_falls_back(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(100)

    def bad(q2):
        raise RuntimeError("boom")

    traj.meta["backbone_fn"] = bad
    with pytest.warns(UserWarning, match="backbone_fn failed"):
        paths = write_figures(traj, tmp_path)
    _check_pngs(paths, tmp_path)


def test_empty_run(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(0, status="error", message="failed before the first step")
    _check_pngs(write_figures(traj, tmp_path), tmp_path)


def test_figures_differ_with_data(tmp_path, synthetic_trajectory):
    """The e2 figure shows the plant-tip curves only when x2_plant exists."""
    a = write_figures(synthetic_trajectory(200), tmp_path / "a")[1]
    b = write_figures(synthetic_trajectory(200, plant=False), tmp_path / "b")[1]
    assert a.read_bytes() != b.read_bytes()
