"""The faster outputs carry the same information (issue: speed end to end).

- figures are drawn from min/max envelopes per display column: every extremum of the full series is
  kept (property test against a plain per-column loop), and the figure data of a real run contain
  the global min/max of every plotted series;
- the 3-D geometry of run.rrd is logged at a display rate while the time series stay at the control
  rate and read back bit-identical to the Trajectory's arrays.
No timings here: speed is measured in benchmarks/bench_core.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from harness.output.decimate import envelope, envelope_indices


# ---------------------------------------------------------------------------------------------
# envelope: pure function
# ---------------------------------------------------------------------------------------------
def _reference_columns(t: np.ndarray, n_columns: int) -> list[np.ndarray]:
    """Sample indices of each column, by a plain loop (the documented binning: column of a sample =
    floor((t - t0) n_columns / (t_end - t0)), the last sample in the last column)."""
    span = t[-1] - t[0]
    cols: dict[int, list[int]] = {}
    for i, ti in enumerate(t):
        c = 0 if span <= 0 else min(int(math.floor((ti - t[0]) / span * n_columns)), n_columns - 1)
        cols.setdefault(c, []).append(i)
    return [np.array(v) for _, v in sorted(cols.items())]


values = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, width=64)


@st.composite
def series(draw):
    n = draw(st.integers(1, 600))
    y = draw(arrays(np.float64, n, elements=values))
    if draw(st.booleans()):  # irregular but non-decreasing times (repeated times allowed)
        t = np.cumsum(draw(arrays(np.float64, n, elements=st.floats(0.0, 3.0))))
    else:
        t = np.arange(n) * 1e-3
    if n > 3 and draw(st.booleans()):  # a NaN tail, as in a diverged run
        y[-draw(st.integers(1, 3)):] = np.nan
    return t, y, draw(st.integers(1, 200))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(series())
def test_envelope_keeps_every_column_extremum(case):
    t, y, n_columns = case
    idx = envelope_indices(t, y, n_columns)
    assert np.all(np.diff(idx) > 0), "indices in time order, no duplicates"
    assert idx.size and idx[0] >= 0 and idx[-1] < len(t)
    kept = set(idx.tolist())
    if len(t) <= 4 * n_columns:
        assert kept == set(range(len(t)))
    assert len(idx) <= 4 * n_columns + int(np.sum(~np.isfinite(y)))
    for col in _reference_columns(t, n_columns):
        assert col[0] in kept and col[-1] in kept  # the joins to the neighbouring columns
        yc = y[col]
        fin = np.isfinite(yc)
        if fin.any():
            kept_vals = y[[i for i in col if i in kept]]
            assert np.nanmin(kept_vals) == yc[fin].min()
            assert np.nanmax(kept_vals) == yc[fin].max()
        assert all(i in kept for i in col[~fin])  # NaN gaps stay where they were
    tk, yk = envelope(t, y, n_columns)
    np.testing.assert_array_equal(tk, t[idx])
    np.testing.assert_array_equal(yk, y[idx])
    if np.isfinite(y).any():
        assert np.nanmax(yk) == np.nanmax(y) and np.nanmin(yk) == np.nanmin(y)


def _documented_envelope_indices(t, y, n_columns):
    """The samples `envelope_indices` documents, by a plain per-column loop over `_reference_columns`:
    every sample when n <= 4 n_columns; otherwise, per column, its first and last sample and the earliest
    sample holding its finite minimum and its finite maximum, plus every non-finite sample."""
    n = len(t)
    if n <= 4 * n_columns:
        return np.arange(n)
    keep = set(np.flatnonzero(~np.isfinite(y)).tolist())
    for col in _reference_columns(t, n_columns):
        keep |= {int(col[0]), int(col[-1])}
        fin = col[np.isfinite(y[col])]
        if fin.size:
            lo, hi = y[fin].min(), y[fin].max()
            keep |= {int(fin[y[fin] == lo][0]), int(fin[y[fin] == hi][0])}
    return np.array(sorted(keep))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(series(), st.booleans())
def test_envelope_indices_are_the_documented_samples(case, ties):
    t, y, n_columns = case
    if ties:  # few distinct values: ties for the min and the max in most columns, and signed zeros
        y = np.where(np.isfinite(y), np.where(y < 0, -0.0, np.minimum(np.round(y), 2.0)), y)  # -0.0, 0, 1, 2
    np.testing.assert_array_equal(envelope_indices(t, y, n_columns),
                                  _documented_envelope_indices(t, y, n_columns))


@pytest.mark.slow
def test_envelope_indices_are_the_documented_samples_on_long_runs():
    rng = np.random.default_rng(7)
    t = np.arange(20_000) * 1e-3
    for y in (np.sin(t * 7.0) + 0.01 * rng.normal(size=t.size), np.round(rng.normal(size=t.size)),
              np.r_[rng.normal(size=15_000), np.full(5_000, np.nan)],
              np.r_[np.inf, -np.inf, rng.normal(size=19_998)]):
        for cols in (1, 7, 910, 1820, 4999):
            np.testing.assert_array_equal(envelope_indices(t, y, cols),
                                          _documented_envelope_indices(t, y, cols))


def test_envelope_reduces_a_long_series():
    t = np.arange(20_000) * 1e-3
    y = np.sin(t * 7.0) + 0.01 * np.random.default_rng(0).normal(size=t.size)
    idx = envelope_indices(t, y, 1000)
    assert len(idx) <= 4000
    assert y[idx].max() == y.max() and y[idx].min() == y.min()


@pytest.mark.parametrize("bad", [0, -3])
def test_envelope_rejects_bad_columns(bad):
    with pytest.raises(ValueError, match="n_columns"):
        envelope_indices(np.arange(10.0), np.arange(10.0), bad)


# ---------------------------------------------------------------------------------------------
# a real short MuJoCo run (shared)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def real_traj():
    from harness.config.scenario import Scenario
    from harness.loop.mujoco_loop import simulate_mujoco

    traj = simulate_mujoco(Scenario(duration=1.0, transient=0.0))
    assert traj.status == "ok" and len(traj) == 1000
    return traj


def test_figure_data_keep_global_extrema_of_a_real_run(tmp_path, monkeypatch, real_traj):
    from harness.output import plots

    monkeypatch.setattr(plots, "COLUMNS_PER_INCH", 20)  # ~140 columns: the 1000-step run is decimated
    figures = {}

    def capture(fig, path):
        figures[path.name] = fig
        return path

    monkeypatch.setattr(plots, "_save", capture)
    plots.write_figures(real_traj, tmp_path)
    tr = real_traj
    e2p = np.asarray(tr.e2_plant)
    expected = {
        "fig2_e1.png": [tr.e1[:, 0], tr.e1[:, 1]],
        "fig3_e2.png": [tr.e2[:, 0], tr.e2[:, 1], e2p[:, 0], e2p[:, 1]],
        "fig4_beta.png": [np.asarray(tr.beta).reshape(-1)],
        "q2.png": [tr.q2[:, i] for i in range(6)],
    }
    for name, want in expected.items():
        lines = [ln for ax in figures[name].axes for ln in ax.get_lines() if len(ln.get_xdata()) > 2]
        lines = [ln for ln in lines if ln.get_linestyle() == "-" or name == "fig3_e2.png"]
        assert len(lines) == len(want), name
        for ln, y in zip(lines, want, strict=True):
            ly = np.asarray(ln.get_ydata(), dtype=float)
            assert len(ly) < len(y), f"{name}: not decimated, the test would prove nothing"
            assert np.nanmax(ly) == np.nanmax(y) and np.nanmin(ly) == np.nanmin(y), (name, ln.get_label())
            assert set(np.asarray(ln.get_xdata())) <= set(tr.t)  # samples of the run, not interpolations


def test_rrd_scalars_bit_exact_with_geometry_at_display_rate(tmp_path, real_traj):
    from rerun.chunk import RrdReader

    from harness.output.record import TIMELINE, geometry_every, read_series, write_recording

    tr = real_traj
    assert geometry_every(tr, 100.0) == 10 and geometry_every(tr, 60.0) == 16  # rate >= the requested one
    assert geometry_every(tr, math.inf) == 1 and geometry_every(tr, 5000.0) == 1
    path = write_recording(tr, tmp_path / "run.rrd", geometry_rate=100.0)
    series = {"e1": tr.e1, "e2": tr.e2, "e2_plant": tr.x1 - tr.x2_plant, "q2": tr.q2, "T1": tr.T1,
              "T2": tr.T2, "beta": np.asarray(tr.beta).reshape(-1, 1), "ya": np.asarray(tr.ya).reshape(-1, 1),
              "deN_norm": np.linalg.norm(tr.deN, axis=1)[:, None]}
    for name, want in series.items():
        t, v = read_series(path, f"plots/{name}")
        np.testing.assert_array_equal(v, np.asarray(want, dtype=np.float64), err_msg=name)
        np.testing.assert_array_equal(np.round(t * 1e9), np.round(tr.t * 1e9))
    want_t = np.round(tr.t[list(range(0, 1000, 10)) + [999]] * 1e9)
    for entity in ("/world/slave/segments", "/world/slave/backbone", "/world/master/arm"):
        t_ns = np.sort(np.concatenate([
            c.to_record_batch().column(TIMELINE).cast("int64").to_numpy()
            for c in RrdReader(path).stream().to_chunks() if c.entity_path == entity and not c.is_static]))
        np.testing.assert_array_equal(t_ns, want_t, err_msg=entity)


def test_run_scenario_writes_geometry_at_the_default_rate(tmp_path, real_traj, monkeypatch):
    """The api writes run.rrd's 3-D scenes at DEFAULT_GEOMETRY_RATE (every 10th control step of 1 kHz,
    plus the last one) and at every step with record_rate = inf.  Read back from the written file: the
    .rrd is written in a child process, so the file is the only witness."""
    from harness import api
    from harness.loop import mujoco_loop
    from harness.output import plots, record

    monkeypatch.setattr(plots, "write_figures", lambda traj, out, names=None: [])  # not this test's subject
    monkeypatch.setattr(mujoco_loop, "simulate_mujoco", lambda scn, **kw: real_traj)
    from rerun.chunk import RrdReader

    from harness.config.scenario import Scenario
    from harness.output.record import TIMELINE

    def scene_times(path):
        return np.sort(np.concatenate([
            c.to_record_batch().column(TIMELINE).cast("int64").to_numpy()
            for c in RrdReader(path).stream().to_chunks() if c.entity_path == "/world/master/arm"
            and not c.is_static]))

    n = len(real_traj)
    every = int(round(1.0 / (record.DEFAULT_GEOMETRY_RATE * 0.001)))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    res = api.run_scenario(Scenario(duration=1.0, transient=0.0), tmp_path / "a", record_rate=None)
    assert not res.failures, res.failures
    want = np.round(real_traj.t[sorted(set(range(0, n, every)) | {n - 1})] * 1e9)
    np.testing.assert_array_equal(scene_times(tmp_path / "a" / "run.rrd"), want)
    res = api.run_scenario(Scenario(duration=1.0, transient=0.0), tmp_path / "b", record_rate=math.inf)
    assert not res.failures, res.failures
    np.testing.assert_array_equal(scene_times(tmp_path / "b" / "run.rrd"), np.round(real_traj.t * 1e9))


@pytest.mark.parametrize("bad", ["0", "-5", "abc", "nan"])
def test_cli_rejects_bad_record_rate(bad, capsys):
    from harness.cli import main

    assert main(["run", "--record-rate", bad, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--record-rate" in err[0] and bad in err[0]


def test_envelope_with_a_subnormal_time_span():
    """Regression (found by hypothesis): n_columns / span overflowed for a subnormal span, and the
    column of every sample became garbage; the binning divides by the span first."""
    from harness.output.decimate import envelope_indices

    t = np.linspace(0.0, 1e-308, 100)
    y = np.sin(np.arange(100.0))
    idx = envelope_indices(t, y, 2)
    assert idx.min() >= 0 and idx.max() <= 99 and len(idx) <= 8
    assert np.argmin(y) in idx and np.argmax(y) in idx


# ---------------------------------------------------------------------------------------------
# outputs written in parallel
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_outputs_written_in_parallel_equal_serial_writes(tmp_path):
    """run_scenario writes run.rrd and the figures in three processes; the PNGs are byte-identical to
    those `write_figures` draws alone in this process from the same trajectory."""
    from harness.api import load_scenario, run_scenario
    from harness.output import plots

    out = tmp_path / "par"
    out.mkdir()
    res = run_scenario(load_scenario(None, ["duration=0.5", "transient=0"]), out)
    assert res.failures == []
    serial = plots.write_figures(res.traj, tmp_path / "ser")
    assert [p.name for p in serial] == [p.name for p in res.written if p.suffix == ".png"]
    for p in serial:
        assert (out / p.name).read_bytes() == p.read_bytes(), p.name
