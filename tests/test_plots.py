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


@pytest.mark.slow
def test_full_run_figures(tmp_path, synthetic_trajectory):
    outdir = tmp_path / "figs"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no matplotlib/numpy warnings on a normal run
        paths = write_figures(synthetic_trajectory(1200), outdir)
    _check_pngs(paths, outdir)


@pytest.mark.slow
@pytest.mark.parametrize("n", [37, 2, 1])
def test_early_stopped_and_tiny_runs(tmp_path, synthetic_trajectory, n):
    traj = synthetic_trajectory(n, status="diverged", message="NaN in qacc", nan_tail=min(4, n - 1))
    _check_pngs(write_figures(traj, tmp_path), tmp_path)


@pytest.mark.slow
def test_analytic_plant_without_meta(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(300, plant=False, with_master_pos=False)
    traj.meta = {}  # no geometry, bases or ranges: defaults must still draw
    _check_pngs(write_figures(traj, tmp_path), tmp_path)


@pytest.mark.slow
def test_broken_backbone_fn_falls_back(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(100)

    def bad(q2):
        raise RuntimeError("boom")

    traj.meta["backbone_fn"] = bad
    with pytest.warns(UserWarning, match="backbone_fn failed"):
        paths = write_figures(traj, tmp_path)
    _check_pngs(paths, tmp_path)


@pytest.mark.slow
def test_empty_run(tmp_path, synthetic_trajectory):
    traj = synthetic_trajectory(0, status="error", message="failed before the first step")
    _check_pngs(write_figures(traj, tmp_path), tmp_path)


@pytest.mark.slow
def test_figures_differ_with_data(tmp_path, synthetic_trajectory):
    """The e2 figure shows the plant-tip curves only when x2_plant exists."""
    a = write_figures(synthetic_trajectory(200), tmp_path / "a")[1]
    b = write_figures(synthetic_trajectory(200, plant=False), tmp_path / "b")[1]
    assert a.read_bytes() != b.read_bytes()


# --- a subset of the figures (names=) ----------------------------------------------------------------
def test_names_draws_only_the_named_figures(tmp_path, synthetic_trajectory):
    from harness.output.plots import FIGURES, figure_names

    traj = synthetic_trajectory(200)
    assert figure_names(traj) == NAMES  # no interaction forces: no forces.png
    paths = write_figures(traj, tmp_path, names=["q2.png", "fig2_e1.png", "forces.png"])
    assert [p.name for p in paths] == ["fig2_e1.png", "q2.png"]  # FIGURES order; forces.png does not apply
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig2_e1.png", "q2.png"]
    assert write_figures(traj, tmp_path / "none", names=[]) == []
    with pytest.raises(ValueError, match="fig9.png") as exc:
        write_figures(traj, tmp_path / "bad", names=["fig2_e1.png", "fig9.png"])
    assert all(n in str(exc.value) for n in FIGURES)  # the message names the allowed ones
    assert not (tmp_path / "bad").exists()  # checked before anything is drawn


# --- nothing clipped or overlapping ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def contact_traj():
    from harness.api import load_scenario
    from harness.loop import simulate

    traj = simulate(load_scenario("scenarios/contact.toml", ["duration=0.4", "transient=0"]))
    assert traj.status == "ok"
    return traj


def _drawn_figures(monkeypatch, traj, outdir):
    """{name: Figure} of write_figures(traj, outdir), each after it was saved (laid out and drawn)."""
    from harness.output import plots

    figures, save = {}, plots._save

    def capture(fig, path):
        out = save(fig, path)
        figures[path.name] = fig
        return out

    monkeypatch.setattr(plots, "_save", capture)
    paths = plots.write_figures(traj, outdir)
    assert [p.name for p in paths] == plots.figure_names(traj) == list(figures)
    return figures


def _texts(fig):
    """(kind, Text or Legend) of every text the figure draws: tick labels in view, axis labels, offset
    texts, titles, legends, suptitle."""
    out = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            tol = 1e-9 * (hi - lo)
            for tick in axis.get_major_ticks():
                if lo - tol <= tick.get_loc() <= hi + tol:
                    out += [("tick", t) for t in (tick.label1, tick.label2)
                            if t.get_visible() and t.get_text()]
            out += [("label", t) for t in (axis.label, axis.offsetText) if t.get_visible() and t.get_text()]
        out += [("label", ax.title)] if ax.title.get_text() else []
        out += [("legend", ax.get_legend())] if ax.get_legend() is not None else []
    if fig._suptitle is not None and fig._suptitle.get_text():
        out.append(("label", fig._suptitle))
    return out


def _check_layout(fig, name):
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    texts = [(kind, t, t.get_window_extent(renderer)) for kind, t in _texts(fig)]
    assert sum(kind == "tick" for kind, _, _ in texts) >= 4, name  # the check saw the tick labels
    for kind, t, bb in texts:
        what = getattr(t, "get_text", lambda: "legend")()
        assert bb.x0 >= canvas.x0 and bb.y0 >= canvas.y0, f"{name}: {kind} {what!r} clipped: {bb} in {canvas}"
        assert bb.x1 <= canvas.x1 and bb.y1 <= canvas.y1, f"{name}: {kind} {what!r} clipped: {bb} in {canvas}"
    # labels, titles, offset texts and the suptitle run into no other text (tick labels may touch each other)
    for i, (ki, ti, bi) in enumerate(texts):
        for kj, tj, bj in texts[i + 1:]:
            if "label" in (ki, kj) and "legend" not in (ki, kj):
                assert not bi.overlaps(bj), f"{name}: {ti.get_text()!r} overlaps {tj.get_text()!r}"


@pytest.mark.slow
@pytest.mark.parametrize("run", ["synthetic", "synthetic_diverged", "contact"])
def test_no_text_is_clipped_or_overlapping(tmp_path, monkeypatch, request, synthetic_trajectory, run):
    traj = {"synthetic": lambda: synthetic_trajectory(1200),
            "synthetic_diverged": lambda: synthetic_trajectory(37, status="diverged", nan_tail=4),
            "contact": lambda: request.getfixturevalue("contact_traj")}[run]()
    figures = _drawn_figures(monkeypatch, traj, tmp_path)
    if run == "contact":
        assert "forces.png" in figures  # the 3-row figure is checked too
    for name, fig in figures.items():
        _check_layout(fig, name)
