"""Surfaces under faults: viewing, sweeps, what a user sees, and files from others (one test per fault
case; the subprocess ones are in the slow tier)."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
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


# ---------------------------------------------------------------------------------------------
# what a user sees: progress bars only on a terminal
# ---------------------------------------------------------------------------------------------
def test_progress_bar_not_drawn_when_stderr_is_not_a_terminal(tmp_path, capsys):
    assert main(["run", "--duration", "0.3", "--out", str(tmp_path / "o")]) == 0  # no --no-progress
    err = capsys.readouterr().err
    assert "step/s" not in err and "%|" not in err and "\r" not in err, err


def test_progress_bar_drawn_on_a_terminal():
    import io

    from harness.config.runtime import progress_bar_class

    class Tty(io.StringIO):
        def isatty(self):
            return True

    for stream, drawn in ((Tty(), True), (io.StringIO(), False)):
        with progress_bar_class()(total=3, file=stream, desc="x", mininterval=0) as bar:
            bar.update(3)
        assert ("3/3" in stream.getvalue()) == drawn


# ---------------------------------------------------------------------------------------------
# viewing
# ---------------------------------------------------------------------------------------------
def _stderr_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


def test_view_without_display_fails_in_one_line_naming_view_web(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "v"
    assert main(["run", "--duration", "0.5", "--view", "--out", str(out), "--no-progress"]) == 1
    (line,) = _stderr_lines(capsys)
    assert line.startswith("error: ") and "--view web" in line and "nothing was run" in line
    assert not any(out.iterdir())  # says it wrote nothing, and did not


@pytest.mark.slow
def test_view_with_a_display_that_fails_is_one_line(tmp_path, capsys, monkeypatch):
    """A display variable that names no X server: the spawned viewer exits, reported in one line."""
    monkeypatch.setenv("DISPLAY", ":93")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["run", "--duration", "0.5", "--view", "--out", str(tmp_path / "v"), "--no-progress"]) == 1
    (line,) = _stderr_lines(capsys)
    assert line.startswith("error: --view: the Rerun viewer exited") and "--view web" in line, line


def test_web_view_port_taken_is_one_line(tmp_path, capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        rc = main(["run", "--duration", "0.2", "--view", "web", "--web-port", str(port), "--grpc-port", "0",
                   "--out", str(tmp_path / "w"), "--no-progress"])
    assert rc == 1
    (line,) = _stderr_lines(capsys)
    assert f"--web-port {port}" in line and "choose another port" in line, line


def _listening(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp*) listening on `port`."""
    found = set()
    for name in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(name) as fh:
            for row in fh.read().splitlines()[1:]:
                local, state = row.split()[1], row.split()[3]
                addr, p = local.rsplit(":", 1)
                if state == "0A" and int(p, 16) == port:
                    found.add(addr)
    return found


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/net/tcp"), reason="reads Linux /proc/net/tcp")
def test_web_view_binds_localhost_and_prints_the_real_address(tmp_path):
    import re
    import signal
    import subprocess
    import sys
    import time
    import urllib.request

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("DISPLAY", None)
    proc = subprocess.Popen([sys.executable, "-m", "harness.cli", "run", "--duration", "0.3", "--view", "web",
                             "--web-port", "0", "--grpc-port", "0", "--out", str(tmp_path / "w"),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)
    try:
        url = None
        deadline = time.monotonic() + 240
        while url is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            assert line, f"teleop ended early ({proc.wait()}): {proc.stdout.read()}"
            if line.startswith("serving the web viewer at "):
                url = line.split()[5]
        m = re.fullmatch(r"http://127\.0\.0\.1:(\d+)/\?url=rerun%2Bhttp%3A%2F%2F127\.0\.0\.1%3A(\d+)"
                         r"%2Fproxy", url)
        assert m, url
        web, grpc = int(m[1]), int(m[2])
        assert web != 0 and grpc != 0
        for port in (web, grpc):
            assert _listening(port) == {"0100007F"}, (port, _listening(port))  # 127.0.0.1 only
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=10) as r:
            assert r.status == 200
        assert (tmp_path / "w" / "metrics.json").is_file()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0
        time.sleep(0.5)
        assert not _listening(web) and not _listening(grpc)  # the server stopped with the run
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_sweep_view_without_display_does_not_say_opened(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    (tmp_path / "recordings").mkdir()
    (tmp_path / "recordings" / "c0001.rrd").write_bytes(b"")
    rc = main(["sweep", str(ROOT / "studies" / "segments.toml"), "--out", str(tmp_path), "--view", "c0001"])
    captured = capsys.readouterr()
    assert rc == 1 and "opened" not in captured.out
    (line,) = [ln for ln in captured.err.splitlines() if ln.strip()]
    assert "no display" in line and "--web-viewer --bind 127.0.0.1" in line, line


# ---------------------------------------------------------------------------------------------
# sweeps: workers die with their parent
# ---------------------------------------------------------------------------------------------
_ORPHAN_SCRIPT = r'''
import os, re, sys, time
from pathlib import Path
from types import SimpleNamespace

from harness.studies import executor

MARK = Path(sys.argv[1])


def case_fn(payload):
    if payload["case_id"] == "boom":
        if not (MARK / "first").exists():
            (MARK / "first").write_text(str(os.getpid()))
            os._exit(9)  # the worker dies: the case is re-run alone in the isolation worker
        (MARK / "isolated").write_text(str(os.getpid()))
        re.match(r"(a+)+$", "a" * 60 + "b")  # blocks in C holding the GIL (like a stuck extension)
    time.sleep(0.2)
    return {"status": "ok", "message": "", "metrics": {}, "traceback": ""}


if __name__ == "__main__":
    cases = [SimpleNamespace(case_id=c, scenario=None) for c in ("a", "boom", "b")]
    runner = executor.Runner(2, None)
    executor.run_cases(runner, case_fn, cases, [], False, lambda case, res: None)
'''


def _descendants(pid: int) -> set[int]:
    parent = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    parent[int(d)] = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                pass
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        kids = {c for c, pp in parent.items() if pp == p}
        out |= kids
        todo += list(kids)
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads Linux /proc")
def test_sweep_workers_die_with_a_killed_parent_during_isolation(tmp_path):
    """kill -9 of the sweep's main process while the isolation worker re-runs a dead worker's case (and
    blocks holding the GIL): the isolation worker and multiprocessing's resource_tracker end too."""
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "orphans.py"
    script.write_text(_ORPHAN_SCRIPT)
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{tmp_path}"}
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path)], env=env, cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "isolated").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "the isolation worker never ran"
            time.sleep(0.1)
        time.sleep(0.5)
        kids = _descendants(proc.pid)
        isolated = int((tmp_path / "isolated").read_text())
        assert isolated in kids
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 5
        while any(_alive(k) for k in kids) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = sorted(k for k in kids if _alive(k))
    finally:
        for k in _descendants(proc.pid) | (kids if "kids" in dir() else set()):
            if _alive(k):
                os.kill(k, signal.SIGKILL)
    assert not left, f"processes left after the sweep's parent was killed: {left}"


# ---------------------------------------------------------------------------------------------
# sweeps: outputs, --set, names, links, time limit
# ---------------------------------------------------------------------------------------------
TINY_STUDY = """
[study]
name = "{name}"
set = ["duration=0.2", "plant.kind='analytic'"]
metrics = ["e2_rms", "sim_time_reached"]
{record}
[[factor]]
name = "seed"
param = "seed"
values = [0, 1]
"""


def _tiny_study(tmp_path: Path, name: str = "tiny", record: str = "") -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_STUDY.format(name=name, record=record))
    return path


def _sweep(argv: list[str]) -> int:
    return main(["sweep", *argv, "--executor", "threads", "--workers", "1", "--no-progress"])


def test_sweep_output_failure_after_the_cases_exits_1_and_writes_the_summary(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "recordings").write_text("a file where the recordings folder goes")
    path = _tiny_study(tmp_path, record='record = {worst = 1, by = "e2_rms"}')
    assert _sweep([str(path), "--out", str(out)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "recordings" in err[0], err
    assert (out / "summary.csv").read_text().count("\n") == 3  # header + 2 cases
    assert len((out / "results.jsonl").read_text().splitlines()) == 2


def test_sweep_set_overrides_the_base_scenario(tmp_path):
    import tomllib

    out = tmp_path / "out"
    assert _sweep([str(_tiny_study(tmp_path)), "--out", str(out), "--set", "duration=0.1"]) == 0
    doc = tomllib.loads((out / "study.toml").read_text())
    assert doc["study"]["set"][-1] == "duration=0.1" and doc["scenario"]["duration"] == 0.1
    rows = [__import__("json").loads(ln) for ln in (out / "results.jsonl").read_text().splitlines()]
    assert len(rows) == 2
    assert all(r["metrics"]["sim_time_reached"] == pytest.approx(0.1, abs=2e-3) for r in rows)


def test_sweep_set_bad_key_is_one_line(tmp_path, capsys):
    rc = _sweep([str(_tiny_study(tmp_path)), "--out", str(tmp_path / "o"), "--set", "plant.segmnts=4"])
    assert rc == 2
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert line.startswith("error: ") and "plant.segmnts" in line and "unknown key" in line
    assert "did you mean 'plant.segments'" in line


@pytest.mark.parametrize("name", ["..", "."])
def test_study_name_cannot_leave_the_output_folder(tmp_path, capsys, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    path = _tiny_study(tmp_path, name=name)
    assert _sweep([str(path)]) == 2
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert "[study] name" in line and "only dots" in line, line
    assert not (tmp_path / "runs").exists()


def test_sweep_refuses_a_planted_results_symlink(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    (out / "results.jsonl").symlink_to(victim)
    assert _sweep([str(_tiny_study(tmp_path)), "--out", str(out)]) == 2
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert "symbolic link" in line and "results.jsonl" in line, line
    assert victim.read_text() == "keep me\n"


def test_sweep_refuses_a_planted_lock_symlink(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    (out / ".lock").symlink_to(victim)
    assert _sweep([str(_tiny_study(tmp_path)), "--out", str(out)]) == 2
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert "symbolic link" in line, line
    assert victim.read_text() == "keep me\n"


def test_case_timeout_makes_an_error_row_and_the_others_run(tmp_path, capsys):
    assert main(["run", "--plant", "analytic", "--duration", "0.1", "--out", str(tmp_path / "warm"),
                 "--no-progress"]) == 0  # kernels loaded (compiled on a cold cache) before the timed sweep
    path = tmp_path / "slow.toml"
    path.write_text(TINY_STUDY.format(name="slow", record="").replace(
        'name = "seed"\nparam = "seed"\nvalues = [0, 1]', 'name = "duration"\nparam = "duration"\n'
        'values = [0.1, 3000.0]'))
    out = tmp_path / "out"
    assert _sweep([str(path), "--out", str(out), "--case-timeout", "3"]) == 0
    import json

    lines = (out / "results.jsonl").read_text().splitlines()
    rows = {r["params"]["duration"]: r for r in map(json.loads, lines)}
    assert rows[0.1]["status"] == "ok"
    assert rows[3000.0]["status"] == "error" and "time limit of 3 s" in rows[3000.0]["message"]
    assert rows[3000.0]["wall_time"] < 60


def blocking_case(case: dict) -> dict:
    """A case function that blocks in C holding the GIL when case_id is 'stuck' (a stuck extension)."""
    import re
    import time

    if case["case_id"] == "stuck":
        re.match(r"(a+)+$", "a" * 60 + "b")
    time.sleep(0.1)
    return {"status": "ok", "message": "", "metrics": {}, "traceback": "", "wall_time": 0.1}


@pytest.mark.slow
def test_case_timeout_stops_a_blocked_worker(monkeypatch):
    from types import SimpleNamespace

    from harness.studies import executor

    monkeypatch.setattr(executor, "HARD_LIMIT_GRACE", 1.0)
    cases = [SimpleNamespace(case_id=c, scenario=None) for c in ("a", "stuck", "b", "c")]
    got = {}
    runner = executor.Runner(2, None)
    try:
        executor.run_cases(runner, blocking_case, cases, [], False,
                           lambda case, res: got.__setitem__(case.case_id, res), time_limit=1.0)
    finally:
        runner.close(cancel=True)
    assert set(got) == {"a", "stuck", "b", "c"}
    assert got["stuck"]["status"] == "error" and "time limit of 1 s" in got["stuck"]["message"]
    assert all(got[c]["status"] == "ok" for c in "abc")


# ---------------------------------------------------------------------------------------------
# what a user sees: obstacles, force arrows, one plane, provenance
# ---------------------------------------------------------------------------------------------
def _columns(path: Path, entity: str, column: str) -> list:
    """Every row of `column` of `entity` in a recording (static and temporal chunks, in file order)."""
    from rerun.chunk import RrdReader

    out = []
    for c in RrdReader(path).stream().to_chunks():
        if c.entity_path == entity:
            batch = c.to_record_batch()
            if column in batch.schema.names:
                out += batch.column(column).to_pylist()
    return out


@pytest.fixture(scope="module")
def contact_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("contact") / "out"
    rc = main(["run", str(ROOT / "scenarios" / "contact.toml"), "--duration", "1.5", "--set", "transient=0",
               "--out", str(out), "--no-progress"])
    assert rc == 0
    return out


def test_contact_obstacle_is_drawn_in_the_3d_and_2d_views(contact_run):
    rrd = contact_run / "run.rrd"
    # the ceiling: plane Z = 0.99 m (slave frame), normal -Z: a slab above it, centred at X = 0
    (centres,) = _columns(rrd, "/world/slave/obstacles/ceiling", "Boxes3D:centers")
    (half,) = _columns(rrd, "/world/slave/obstacles/ceiling", "Boxes3D:half_sizes")
    from harness.output.geometry import PLANE_THICKNESS

    slave_base = np.array([0.0, 0.3, 0.0])  # octarm_base of the generated MuJoCo model
    np.testing.assert_allclose(centres[0], slave_base + [0.0, 0.0, 0.99 + PLANE_THICKNESS / 2], atol=1e-6)
    assert half[0][0] >= 0.5 and half[0][2] == pytest.approx(PLANE_THICKNESS / 2)
    (strips,) = _columns(rrd, "/traces/obstacles/ceiling", "LineStrips2D:strips")
    pts = np.array(strips[0])
    assert np.allclose(pts[:, 1], -0.99, atol=1e-6)  # the wall's face: the line Z = 0.99 (screen y = -Z)


def test_contact_obstacle_is_drawn_in_the_shapes_figure(contact_run, tmp_path):
    import matplotlib.image as mpimg

    from harness.loop.trajectory import Trajectory  # noqa: F401 - the figure's input type
    from harness.output import plots

    edge = np.round(np.array(plots.OBSTACLE_EDGE[:3]) * 255)

    def edge_pixels(path: Path) -> int:
        img = mpimg.imread(path)[..., :3] * 255
        return int((np.abs(img - edge).max(axis=-1) < 6).sum())

    assert edge_pixels(contact_run / "shapes.png") > 200  # the outline of the ceiling
    assert edge_pixels(contact_run / "fig3_e2.png") == 0  # the colour is not used elsewhere


def test_contact_force_arrows_are_scaled_to_be_seen(contact_run):
    from harness.output.record import ARROW_LENGTH

    vectors = [np.array(v) for v in _columns(contact_run / "run.rrd", "/world/contact/forces",
                                             "Arrows3D:vectors") if v]
    longest = max(float(np.linalg.norm(v, axis=1).max()) for v in vectors)
    # the largest force of the run is ARROW_LENGTH long (a sixth of the arm); arrows are drawn every
    # CONTACT_EVERY-th step, so the longest drawn one may be a little shorter
    assert 0.9 * ARROW_LENGTH <= longest <= ARROW_LENGTH * (1 + 1e-6)
    (status,) = _columns(contact_run / "run.rrd", "/status", "TextDocument:text")
    assert "contact force arrows: 1 N =" in status[0]


def test_both_arms_are_drawn_in_one_plane(contact_run):
    """The 3-D view's master tip and slave tip (after the arms' display transforms) lie in one plane Y = const
    and differ in X-Z by e2_plant = x1 - x2_plant: with e2 of a few mm they are drawn a few mm apart."""
    import json

    rrd = contact_run / "run.rrd"
    (tm,) = _columns(rrd, "/world/master", "Transform3D:translation")
    (ts,) = _columns(rrd, "/world/slave", "Transform3D:translation")
    master_tip = np.array([p[0] for p in _columns(rrd, "/world/master/tip", "Points3D:positions")]) + tm
    slave_tip = np.array([p[0] for p in _columns(rrd, "/world/slave/tip", "Points3D:positions")]) + ts
    assert len(master_tip) == len(slave_tip) > 100
    np.testing.assert_allclose(master_tip[:, 1], slave_tip[:, 1], atol=1e-6)
    gap = np.linalg.norm((master_tip - slave_tip)[:, [0, 2]], axis=1)
    metrics = json.loads((contact_run / "metrics.json").read_text())
    assert gap.max() <= metrics["e2_plant_max"] + 1e-5


def test_version_and_git_revision_in_metrics_and_config(contact_run):
    import json
    import subprocess
    from importlib.metadata import version

    from harness.api import load_scenario

    tool = json.loads((contact_run / "metrics.json").read_text())["tool"]
    assert tool["name"] == "octarm-teleop" and tool["version"] == version("octarm-teleop")
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode == 0:  # run from a checkout
        assert tool["git_revision"] == head.stdout.strip()
    first = (contact_run / "config.toml").read_text().splitlines()[0]
    assert first.startswith("# written by octarm-teleop " + tool["version"])
    assert ("git_revision" not in tool) or tool["git_revision"] in first
    assert load_scenario(contact_run / "config.toml").name == "contact"  # still a scenario file


def test_git_revision_absent_outside_a_checkout_never_an_error(tmp_path):
    from harness.config.runtime import _git_revision

    assert _git_revision(tmp_path) is None
    (tmp_path / ".git").write_text("gitdir: /nonexistent/place\n")
    with pytest.raises(OSError):
        _git_revision(tmp_path)  # provenance() catches this: the revision is then absent
    (tmp_path / ".git").write_text("garbage")
    assert _git_revision(tmp_path) is None


def test_web_view_on_another_address_warns(tmp_path, capsys, monkeypatch):
    """--view-host other than loopback: a warning line says the run is served to other machines (the
    viewer itself is replaced by a file stream here)."""
    from harness.output import viewer

    seen = {}

    def to_file(mode, scn, **kw):
        seen.update(kw, mode=mode)
        return viewer.LiveView.to_file(tmp_path / "live.rrd", scn)

    monkeypatch.setattr(viewer.LiveView, "open", staticmethod(to_file))
    rc = main(["run", "--duration", "0.2", "--view", "web", "--view-host", "0.0.0.0",
               "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc == 0 and seen["host"] == "0.0.0.0" and seen["mode"] == "web"
    err = capsys.readouterr().err.splitlines()
    warn = [ln for ln in err if ln.startswith("warning: --view-host 0.0.0.0")]
    assert len(warn) == 1 and "every machine" in warn[0], err
    assert (tmp_path / "o" / "metrics.json").is_file()


@pytest.mark.parametrize("host, text", [("no.such.host.invalid", "not an address"),
                                        ("192.0.2.1", "not an address of this machine")])
def test_web_view_bad_host_is_one_line(tmp_path, capsys, host, text):
    rc = main(["run", "--duration", "0.2", "--view", "web", "--view-host", host, "--out", str(tmp_path / "o"),
               "--no-progress"])
    assert rc == 1
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert line.startswith(f"error: --view-host {host}: {text}"), line


@pytest.fixture
def xvfb_display():
    """A virtual X display (Xvfb), so that the native viewer is really started; skipped without Xvfb."""
    import shutil
    import subprocess
    import time

    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("no Xvfb binary (apt-get install xvfb)")
    for n in range(70, 90):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            break
    proc = subprocess.Popen([exe, f":{n}", "-screen", "0", "1280x800x24"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 20
    while not os.path.exists(f"/tmp/.X11-unix/X{n}"):
        assert proc.poll() is None and time.monotonic() < deadline, "Xvfb did not start"
        time.sleep(0.1)
    yield f":{n}"
    proc.terminate()
    proc.wait(10)


@pytest.mark.slow
def test_native_view_on_a_display_works_or_fails_in_one_line(tmp_path, capsys, monkeypatch, xvfb_display):
    """On a real X display the native viewer is started: either the run streams to it and writes its
    outputs (exit 0), or the viewer cannot run there (software GL without the texture formats it needs,
    as on this machine kind) and that is one line naming --view web, before anything runs."""
    monkeypatch.setenv("DISPLAY", xvfb_display)
    out = tmp_path / "v"
    rc = main(["run", "--duration", "0.5", "--view", "--out", str(out), "--no-progress"])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    if rc == 0:
        assert (out / "metrics.json").is_file() and (out / "run.rrd").is_file()
    else:
        assert rc == 1 and len(err) == 1, err
        assert err[0].startswith("error: --view: the Rerun viewer exited") and "--view web" in err[0]
        assert not any(out.iterdir())
    # a sweep's recording: opened, or one line without "opened"
    (tmp_path / "recordings").mkdir()
    (tmp_path / "recordings" / "c1.rrd").write_bytes(b"")
    rc = main(["sweep", str(ROOT / "studies" / "segments.toml"), "--out", str(tmp_path), "--view", "c1"])
    captured = capsys.readouterr()
    assert (rc == 0 and "opened" in captured.out) or (rc == 1 and "opened" not in captured.out
                                                      and len(captured.err.strip().splitlines()) == 1)


def test_live_view_of_a_contact_run_streams_the_obstacle_and_forces(tmp_path, monkeypatch):
    from harness.output import viewer

    monkeypatch.setattr(viewer.LiveView, "open", staticmethod(
        lambda mode, scn, **kw: viewer.LiveView.to_file(tmp_path / "live.rrd", scn)))
    assert main(["run", str(ROOT / "scenarios" / "contact.toml"), "--duration", "1.5", "--set", "transient=0",
                 "--view", "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    live = tmp_path / "live.rrd"
    assert _columns(live, "/world/slave/obstacles/ceiling", "Boxes3D:half_sizes")
    assert _columns(live, "/traces/obstacles/ceiling", "LineStrips2D:strips")
    assert len(_columns(live, "/plots/forces/F2", "Scalars:scalars")) == 1500


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
@pytest.mark.parametrize("kind", ["device", "socket"])
def test_device_or_socket_as_scenario_is_refused_in_one_line(tmp_path, capsys, kind):
    import socket

    if kind == "device":
        path, sock = Path("/dev/zero"), None
    else:
        path = tmp_path / "s.toml"
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(path))
    try:
        assert _main_within(["run", str(path), "--out", str(tmp_path / "o"), "--no-progress"], 20.0) == 2
    finally:
        if sock is not None:
            sock.close()
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert "not a regular file" in line and str(path) in line, line
