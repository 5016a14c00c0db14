"""The faster outputs carry the same information (issue: speed end to end).

- the figures of a real run draw every sample of every plotted series;
- the 3-D geometry of run.rrd is logged at a display rate while the time series stay at the control
  rate and read back bit-identical to the Trajectory's arrays.
No timings here: speed is measured in benchmarks/bench_core.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest


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


def test_figure_data_are_every_sample_of_a_real_run(tmp_path, monkeypatch, real_traj):
    from harness.output import plots

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
            np.testing.assert_array_equal(np.asarray(ln.get_ydata(), dtype=float), y, err_msg=name)
            np.testing.assert_array_equal(np.asarray(ln.get_xdata(), dtype=float), tr.t, err_msg=name)


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
