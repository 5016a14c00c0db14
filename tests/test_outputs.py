"""Outputs never lie: atomic writes, full disks, kills, interrupts, reused folders, guarded
writes, input size/depth limits, plant errors as validation, sweep case cap / scheduler check /
orphaned workers.

The fault tests run `teleop` in subprocesses: a full disk is a file-size limit (RLIMIT_FSIZE, what
`ulimit -f` sets) in the child; kills are SIGKILL.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import textwrap
import threading
import time
import tomllib
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from harness.api import load_scenario, run_scenario
from harness.cli import main
from harness.config.errors import ConfigError
from harness.config.textio import MAX_DEPTH, TMP_MARK, OutputError, write_atomic
from harness.output.guarded import start_in_child

ROOT = Path(__file__).resolve().parents[1]
TELEOP = [sys.executable, "-m", "harness.cli"]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))
ANALYTIC = ["--plant", "analytic", "--no-progress"]


def _teleop(args, *, cwd=ROOT, timeout=300, fsize: int | None = None):
    def limit():
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    return subprocess.run([*TELEOP, *map(str, args)], cwd=cwd, env=ENV, capture_output=True, text=True,
                          timeout=timeout, preexec_fn=limit)


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1, err
    assert "Traceback" not in err, err
    return lines[0]


def _temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(f"*{TMP_MARK}*")]


def _check_complete(out: Path) -> None:
    """Every file under a final name is complete: TOML/JSON parse, the recording reads back, PNGs end
    with their IEND chunk."""
    for p in out.iterdir():
        if TMP_MARK in p.name:
            continue
        if p.name == "config.toml":
            tomllib.loads(p.read_text())
        elif p.name == "metrics.json":
            json.loads(p.read_text())
        elif p.suffix == ".rrd":
            RrdReader(p).stream()
        elif p.suffix == ".png":
            assert p.read_bytes().endswith(b"IEND\xaeB`\x82"), p


# --- the atomic writer ------------------------------------------------------------------------------
def test_write_atomic_replaces_only_when_complete(tmp_path):
    p = tmp_path / "a.txt"
    write_atomic(p, "old")

    def failing(tmp: Path) -> None:
        tmp.write_text("partial")
        raise OSError(28, "No space left on device")

    with pytest.raises(OutputError, match=r"cannot write .*a\.txt: No space left on device"):
        write_atomic(p, failing)
    assert p.read_text() == "old" and _temps(tmp_path) == []
    with pytest.raises(OutputError, match="cannot write"):
        write_atomic(tmp_path / "missing" / "b.txt", "x")


def test_kill_9_of_a_writer_leaves_no_file_under_its_final_name(tmp_path):
    target = tmp_path / "big.bin"
    code = textwrap.dedent(f"""
        import sys, time
        from harness.config.textio import write_atomic
        def slow(tmp):
            with open(tmp, "wb") as fh:
                for _ in range(1000):
                    fh.write(b"x" * 65536); fh.flush(); print("chunk", flush=True); time.sleep(0.01)
        write_atomic({str(target)!r}, slow)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], env=ENV, stdout=subprocess.PIPE, text=True)
    for _ in range(5):  # it is writing
        proc.stdout.readline()
    proc.kill()
    proc.wait(10)
    assert not target.exists()
    assert _temps(tmp_path), "the partial file should be under its temporary name"


@pytest.mark.slow
@pytest.mark.parametrize("delay", [2.0, 4.0])
def test_kill_9_of_a_run_leaves_only_complete_files(tmp_path, delay):
    out = tmp_path / "o"
    proc = subprocess.Popen([*TELEOP, "run", *ANALYTIC, "--duration", "8", "--out", str(out)], cwd=ROOT,
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while not (out / "config.toml").exists() and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(delay)
    proc.kill()
    proc.wait(10)
    _check_complete(out)
    if (out / "metrics.json").exists():  # written last: then every output it lists is there
        doc = json.loads((out / "metrics.json").read_text())
        assert all((out / n).exists() for n in doc["outputs"])


# --- full disk, stalls, interrupts ------------------------------------------------------------------
@pytest.mark.slow
def test_full_disk_is_reported_not_hung(tmp_path):
    """A 1 MB file-size limit: the ~1.6 MB recording cannot be written, the small files can."""
    warm = _teleop(["run", *ANALYTIC, "--duration", "0.2", "--out", tmp_path / "warm"])  # numba cache
    assert warm.returncode == 0, warm.stderr
    out = tmp_path / "o"
    t0 = time.monotonic()
    # every step's 3-D scene (--record-rate full): a recording larger than the limit
    res = _teleop(["run", *ANALYTIC, "--duration", "2", "--record-rate", "full", "--out", out],
                  fsize=1_000_000, timeout=240)
    took = time.monotonic() - t0
    assert res.returncode == 1, res.stderr
    line = _one_error_line(res.stderr)
    assert "could not be produced" in line
    assert "could not produce run.rrd: cannot write" in res.stderr and "Traceback" not in res.stderr
    assert "File too large" in res.stderr  # the cause, from the file sink's own log line
    assert "ERROR" not in res.stderr  # ... which is not printed raw
    assert not (out / "run.rrd").exists() and _temps(out) == []
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["outputs_failed"] == ["run.rrd"] and "run.rrd" not in doc["outputs"]
    assert all((out / n).exists() for n in doc["outputs"])
    _check_complete(out)
    print(f"full-disk run reported in {took:.1f} s")


@pytest.mark.slow
def test_stalled_writer_is_killed_and_reported(tmp_path):
    t0 = time.monotonic()
    with pytest.raises(OutputError, match="no progress for 1 s"):
        start_in_child(lambda: time.sleep(60), tmp_path / "x.rrd", stall_timeout=1.0).wait()
    assert time.monotonic() - t0 < 10
    assert not (tmp_path / "x.rrd").exists()


def test_failing_child_writer_is_one_line(tmp_path):
    def fail():
        raise OSError(27, "File too large")

    with pytest.raises(OutputError, match=r"cannot write .*x\.rrd: File too large"):
        start_in_child(fail, tmp_path / "x.rrd").wait()


@pytest.fixture
def python_sigint():
    """Python's own SIGINT handler for the test, also where the runner was started with SIGINT ignored
    (a background job of a non-interactive shell, where a SIGINT would otherwise be dropped and the
    test below would wait for its blocked child for ever)."""
    prev = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, prev)


def test_ctrl_c_ends_a_blocked_writer(tmp_path, python_sigint):
    pid_file = tmp_path / "pid"

    def blocked():
        tmp = pid_file.with_suffix(".tmp")
        tmp.write_text(str(os.getpid()))
        tmp.rename(pid_file)
        while True:
            time.sleep(1)

    def interrupt():
        deadline = time.time() + 30
        while not pid_file.exists() and time.time() < deadline:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        start_in_child(blocked, tmp_path / "x.rrd", stall_timeout=600).wait()
    child = int(pid_file.read_text())
    assert not _alive(child), Path(f"/proc/{child}/status").read_text()  # killed


def test_child_writers_run_at_the_same_time(tmp_path):
    """start_in_child returns at once: two children that each wait for the other's file can only both
    finish if they run concurrently (with the parent free meanwhile)."""
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"

    def writer(mine, other):
        def fn():
            mine.write_text("x")
            deadline = time.time() + 20
            while not other.exists():
                if time.time() > deadline:
                    raise OSError(62, "the other writer never ran")
                time.sleep(0.01)
        return fn

    ca = start_in_child(writer(a, b), a, stall_timeout=None)
    cb = start_in_child(writer(b, a), b, stall_timeout=None)
    assert ca.wait() == a and cb.wait() == b


@pytest.mark.parametrize("broken_fig, name", [("fig_e2", "fig3_e2.png"), ("fig_q2", "q2.png")],
                         ids=["in-the-child", "in-the-parent"])
def test_failed_figure_is_reported_and_the_rest_written(tmp_path, monkeypatch, broken_fig, name):
    """A figure fails, drawn in the forked figure child or in the run's process: 'figures' is reported
    once; every other output is written and listed (run.rrd, the other drawer's figures, the figures
    drawn before the failing one in its own group); what metrics.json lists exists; no temporary file
    is left."""
    from harness import api
    from harness.output import plots

    def broken(*args, **kwargs):
        raise RuntimeError("drawing failed on purpose")

    monkeypatch.setattr(plots, broken_fig, broken)
    out = tmp_path / "o"
    out.mkdir()
    scn = load_scenario(None, ["plant.kind='analytic'", "duration=0.3", "transient=0"])
    res = run_scenario(scn, out)
    assert len(res.failures) == 1 and res.failures[0].startswith("figures: ")
    assert "drawing failed on purpose" in res.failures[0]
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["outputs_failed"] == ["figures"]
    assert name not in doc["outputs"] and not (out / name).exists()
    order = ["fig2_e1.png", "fig3_e2.png", "fig4_beta.png", "q2.png", "shapes.png"]
    group = [n for n in order if (n in api.FIGURES_IN_CHILD) == (name in api.FIGURES_IN_CHILD)]
    other = [n for n in order if n not in group]
    before = group[:group.index(name)]
    assert other, "both drawers have figures"
    for n in ("config.toml", "run.rrd", *other, *before, "metrics.json"):
        assert n in doc["outputs"], n
    assert all((out / n).exists() for n in doc["outputs"])
    _check_complete(out)


# --- reused output folders --------------------------------------------------------------------------
def test_reused_out_holds_only_the_current_run(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    for name in ("fig9_old.png", "shapes.png", "run.rrd", f".run.rrd{TMP_MARK}1-0"):
        (out / name).write_bytes(b"stale")
    (out / "metrics.json").write_text(json.dumps({"outputs": ["fig9_old.png"]}))
    (out / "notes.txt").write_text("mine")
    scn = load_scenario(None, ["plant.kind='analytic'", "duration=0.3"])
    res = run_scenario(scn, out)
    assert res.failures == []
    names = sorted(p.name for p in out.iterdir())
    doc = json.loads((out / "metrics.json").read_text())
    assert names == sorted([*doc["outputs"], "notes.txt"])  # the user's file is kept, nothing stale
    assert doc["outputs_failed"] == []
    assert (out / "shapes.png").read_bytes() != b"stale"
    _check_complete(out)


# --- guarded writes: one line, exit 2 ---------------------------------------------------------------
def test_unwritable_config_is_one_line_exit_2(tmp_path, capsys):
    out = tmp_path / "o"
    (out / "config.toml").mkdir(parents=True)  # a folder where the file should go
    assert main(["run", *ANALYTIC, "--duration", "0.2", "--out", str(out)]) == 2
    assert "config.toml" in _one_error_line(capsys.readouterr().err)


def test_models_out_errors_are_one_line(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["models", "--segments", "2", "--out", str(blocker / "x.xml")]) == 2
    assert "file" in _one_error_line(capsys.readouterr().err)
    assert main(["models", "--segments", "2", "--out", str(tmp_path / "m.xml")]) == 0
    assert (tmp_path / "m.xml").read_text().lstrip().startswith("<mujoco") and _temps(tmp_path) == []


def test_sweep_study_toml_write_failure_is_one_line(tmp_path, capsys):
    study = tmp_path / "s.toml"
    study.write_text('[study]\nname = "s"\nset = ["plant.kind=\\"analytic\\"", "duration=0.2"]\n'
                     '[[factor]]\nparam = "seed"\nvalues = [1]\n')
    out = tmp_path / "o"
    (out / "study.toml").mkdir(parents=True)
    assert main(["sweep", str(study), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    assert "study.toml" in _one_error_line(capsys.readouterr().err)
    assert _temps(out) == []


# --- input limits -----------------------------------------------------------------------------------
def _deep(depth: int) -> str:
    return "[" * depth + "]" * depth


@pytest.mark.parametrize("depth", [MAX_DEPTH + 1, 2000])
@pytest.mark.parametrize("kind", ["scenario", "bounds", "study", "set"])
def test_deep_nesting_is_one_line(tmp_path, capsys, kind, depth):
    f = tmp_path / "deep.toml"
    f.write_text(f"x = {_deep(depth)}\n")
    args = {"scenario": ["run", f], "bounds": ["check", "--bounds", f], "study": ["sweep", f],
            "set": ["run", "--set", f"duration={_deep(depth)}"]}[kind]
    assert main([*map(str, args), "--out", str(tmp_path / "o")]) == 2
    assert f"nested deeper than {MAX_DEPTH}" in _one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


def test_nesting_at_the_limit_is_not_refused_for_depth():
    # 31 arrays inside the document table: within the limit; refused for its *value* instead
    with pytest.raises(ConfigError) as e:
        load_scenario({"duration": eval(_deep(MAX_DEPTH - 1))})
    assert "nested deeper" not in str(e.value) and "duration" in str(e.value)


@pytest.mark.parametrize("kind", ["scenario", "bounds", "study"])
def test_oversized_documents_are_one_line(tmp_path, capsys, kind):
    f = tmp_path / "big.toml"
    f.write_text("# " + "x" * (1 << 20) + "\n")
    args = {"scenario": ["run", f], "bounds": ["check", "--bounds", f], "study": ["sweep", f]}[kind]
    assert main([*map(str, args), "--out", str(tmp_path / "o")]) == 2
    assert "larger than the limit of 1048576 bytes" in _one_error_line(capsys.readouterr().err)


# --- plant errors are validation --------------------------------------------------------------------
@pytest.mark.parametrize("override, expected", [
    ("plant.slave.masses=[1e-300,0.84,0.48]",
     "plant.slave.masses[0] = 1e-300: too small for the plant model"),
    ("plant.slave.masses=[1.2,0.84,1e-20]", "plant.slave.masses[2] = 1e-20: too small for the plant model"),
    ("plant.master.masses=[1.0,1e-300]", "plant.master.masses[1] = 1e-300: too small for the plant model"),
    ("plant.master.gravity=5.0", "plant.master.gravity = 5 and plant.slave.gravity = [0, -9.81] differ"),
    ("plant.slave.gravity=[0.0,-5.0]", "plant.slave.gravity = [0, -5] differ"),
])
def test_plant_errors_name_the_field_before_anything_is_written(tmp_path, capsys, override, expected):
    out = tmp_path / "o"
    assert main(["run", "--set", override, "--duration", "0.2", "--no-progress", "--out", str(out)]) == 2
    assert expected in _one_error_line(capsys.readouterr().err)
    assert not out.exists()


# --- sweeps -----------------------------------------------------------------------------------------
def _study(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "study.toml"
    p.write_text('[study]\nname = "cap"\nset = ["plant.kind=\\"analytic\\"", "duration=0.2"]\n' + body)
    return p


def test_case_cap_is_checked_before_expansion(tmp_path, capsys):
    levels = ", ".join(str(1 + i / 1000) for i in range(100))
    body = "".join(f'[[factor]]\nparam = "plant.slave.masses[{i}]"\nscale = [{levels}]\n' for i in range(3))
    out = tmp_path / "o"
    t0 = time.monotonic()
    assert main(["sweep", str(_study(tmp_path, body)), "--out", str(out), "--no-progress"]) == 2
    assert "1000000 cases, more than the limit of 10000" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()
    print(f"refused in {time.monotonic() - t0:.1f} s")
    rand = _study(tmp_path, '[[factor]]\nparam = "seed"\nvalues = {random = "integers", low = 0, high = 9}\n'
                            '[sampling]\nmode = "random"\nn = 100000000\n')
    assert main(["sweep", str(rand), "--out", str(out), "--no-progress"]) == 2
    assert "100000000 cases" in _one_error_line(capsys.readouterr().err)


def test_max_cases_option_and_table(tmp_path, capsys):
    body = '[[factor]]\nparam = "seed"\nvalues = [1, 2, 3]\n'
    assert main(["sweep", str(_study(tmp_path, body)), "--max-cases", "2", "--out", str(tmp_path / "o"),
                 "--no-progress"]) == 2
    assert "3 cases, more than the limit of 2" in _one_error_line(capsys.readouterr().err)
    assert main(["sweep", str(_study(tmp_path, body + "[sampling]\nmax_cases = 0\n")), "--no-progress"]) == 2
    assert "max_cases = 0" in _one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_unreachable_scheduler_is_found_before_any_file(tmp_path, capsys):
    out = tmp_path / "o"
    t0 = time.monotonic()
    study = _study(tmp_path, '[[factor]]\nparam = "seed"\nvalues = [1]\n')
    assert main(["sweep", str(study), "--out", str(out), "--scheduler", "tcp://127.0.0.1:9",
                 "--no-progress"]) == 2
    took = time.monotonic() - t0
    assert "cannot connect to the Dask scheduler" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()
    print(f"unreachable scheduler reported in {took:.1f} s")


@pytest.mark.slow
def test_pool_workers_end_when_the_main_process_is_killed(tmp_path):
    (tmp_path / "slowcase.py").write_text(textwrap.dedent("""
        import os, time
        from pathlib import Path
        def case(payload):
            Path(os.environ["PID_DIR"], str(os.getpid())).write_text("")
            time.sleep(120)
            return {"status": "ok", "metrics": {}}
    """))
    pids = tmp_path / "pids"
    pids.mkdir()
    study = _study(tmp_path, '[[factor]]\nparam = "seed"\nvalues = [1, 2, 3, 4]\n')
    code = textwrap.dedent(f"""
        from harness.studies.sweep import run_sweep
        from slowcase import case
        if __name__ == "__main__":
            run_sweep({str(study)!r}, {str(tmp_path / 'o')!r}, workers=2, progress=False, case_fn=case)
    """)
    script = tmp_path / "main.py"
    script.write_text(code)
    env = dict(ENV, PYTHONPATH=f"{ROOT}{os.pathsep}{tmp_path}", PID_DIR=str(pids))
    proc = subprocess.Popen([sys.executable, str(script)], env=env, cwd=tmp_path)
    try:
        deadline = time.time() + 120
        while len(list(pids.iterdir())) < 2 and time.time() < deadline:
            time.sleep(0.1)
        workers = [int(p.name) for p in pids.iterdir()]
        assert len(workers) == 2
        proc.kill()
        proc.wait(10)
        deadline = time.time() + 10
        while time.time() < deadline and any(_alive(p) for p in workers):
            time.sleep(0.1)
        assert not any(_alive(p) for p in workers), "pool workers outlived the killed main process"
    finally:
        if proc.poll() is None:
            proc.kill()


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state  # a zombie has ended
