"""Ahead-of-time compiled entry kernels (`harness.loop.aot`): the same numbers as the jitted kernels,
found without numba, releasing the GIL, and a jitted fallback when they cannot be built."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import harness.loop.mujoco_loop as mujoco_loop
from harness.config.scenario import PlantConfig, Scenario
from harness.loop import aot, simulate
from harness.loop.trajectory import Trajectory

ROOT = Path(__file__).resolve().parent.parent


def _c_toolchain() -> str | None:
    """Why this machine cannot build the modules (no C compiler or no Python headers), or None.  Only
    the environment is checked here, so a broken build on a machine that can build still fails."""
    import shutil
    import sysconfig

    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(cc) is None:
        return f"no C compiler ({cc!r} not found)"
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").exists():
        return "no Python headers (Python.h)"
    return None


def _needs_modules() -> None:
    if os.environ.get("TELEOP_NO_JIT") == "1":
        pytest.skip("interpreted kernels requested (TELEOP_NO_JIT=1)")
    why = _c_toolchain()
    if why:
        pytest.skip(f"ahead-of-time modules cannot be built here: {why} (the fallback is "
                    "test_build_failure_falls_back_to_jit)")


def _samples() -> list:
    a = np.arange(12.0).reshape(3, 4)
    ro = np.arange(5.0)
    ro.setflags(write=False)
    raw = np.zeros(8 * 6 + 1, dtype=np.uint8)
    unaligned = raw[1:].view(np.float64)
    return [
        np.zeros(3), np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int32), np.zeros(3, dtype=bool),
        np.zeros((0, 7)), np.zeros(()), a, a.T, a[:, ::2], a[::2], np.asfortranarray(a), ro, ro[::2],
        unaligned, np.zeros((2, 3, 4)), 1, -(2 ** 40), True, False, 2.5, np.float64(1.0), np.int64(3),
        np.int32(3), np.bool_(True), (), (1, 2.0), (np.zeros(2), np.zeros(2)), (np.zeros(2), ro),
        ((1, 2), np.zeros((1, 1))), (True, 1), (1, True),
    ]


def test_type_key_determines_numba_type():
    """Equal keys imply equal numba argument types, over arrays of every dtype/ndim/layout/writeable/
    alignment and scalars and nested tuples the loops pass (a key finer than the type only costs an
    extra module; a coarser one would call a module with the wrong types)."""
    numba = pytest.importorskip("numba")
    samples = _samples()
    keys = [aot.type_key(s) for s in samples]
    types = [numba.typeof(s) for s in samples]
    for i in range(len(samples)):
        for j in range(len(samples)):
            if keys[i] == keys[j]:
                assert types[i] == types[j], (keys[i], types[i], types[j])
    # and the key tells apart what numba tells apart among the arrays
    arrays = [i for i, s in enumerate(samples) if isinstance(s, np.ndarray)]
    assert len({keys[i] for i in arrays}) == len({types[i] for i in arrays})


@pytest.mark.parametrize("bad", [None, [1.0], {"a": 1}, 2 ** 70, "x", np.zeros(2, dtype=[("a", "f8")]),
                                 np.zeros(2, dtype=object)])
def test_type_key_refuses_other_arguments(bad):
    with pytest.raises(aot.Unsupported):
        aot.type_key((np.zeros(2), bad))


def _run(scn: Scenario, no_aot: bool, monkeypatch) -> Trajectory:
    monkeypatch.setenv("TELEOP_NO_AOT", "1" if no_aot else "0")
    aot.forget()
    try:
        return simulate(scn, progress=False)
    finally:
        aot.forget()


CASES = {
    "mujoco_servo": Scenario(duration=0.6),
    "mujoco_torque": Scenario(duration=0.3, plant=PlantConfig(actuation="torque")),
    # rk4 integrates the servos' gains explicitly, and per unit length they are too stiff for it on the
    # light distal joints: the rk4 case runs torque actuation
    "mujoco_rk4_cc": Scenario(duration=0.3, plant=PlantConfig(integrator="rk4", enforce_cc=True,
                                                            actuation="torque")),
    "analytic": Scenario(duration=0.6, plant=PlantConfig(kind="analytic")),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_aot_run_bit_identical_to_jit(name, monkeypatch, traj_arrays):
    """Every array of the Trajectory (states, errors, commands, plant geometry) is bit-identical with
    the ahead-of-time modules and with the jitted kernels; the AOT path really ran compiled modules."""
    _needs_modules()
    scn = CASES[name]
    a = _run(scn, False, monkeypatch)
    b = _run(scn, True, monkeypatch)
    assert a.status == b.status == "ok"
    fa, fb = traj_arrays(a), traj_arrays(b)
    assert fa.keys() == fb.keys() and len(fa) > 10
    for k in fa:
        assert np.array_equal(fa[k], fb[k], equal_nan=True), k


def _from_built_module(fn) -> bool:
    """Whether `fn` comes from an ahead-of-time module built in the cache (an extension file there, named
    after the module that defines `fn`)."""
    return any(aot.aot_dir().glob(f"{fn.__module__}.*"))


def test_aot_path_resolves_extension_modules(monkeypatch):
    _needs_modules()
    monkeypatch.setenv("TELEOP_NO_AOT", "0")
    aot.forget()
    simulate(Scenario(duration=0.1), progress=False)
    fns = [fn for e in aot.A._entries.values() for fn in e._fns.values()]  # noqa: SLF001
    aot.forget()
    assert fns and all(_from_built_module(fn) for fn in fns), fns


@pytest.mark.slow
def test_run_does_not_import_numba():
    """A MuJoCo run with the modules built imports neither numba nor SciPy (their ~1.2-1.5 s start-up
    is what the modules save)."""
    _needs_modules()
    simulate(Scenario(duration=0.05), progress=False)  # builds the modules if missing (in this process)
    code = ("import sys; from harness.loop import simulate; from harness.config.scenario import Scenario; "
            "tr = simulate(Scenario(duration=0.2), progress=False); "
            "print(tr.status, 'numba' in sys.modules, 'scipy' in sys.modules, 'llvmlite' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TELEOP_NO_AOT": "0"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["ok", "False", "False", "False"], out.stdout + out.stderr


def test_aot_kernel_releases_the_gil(monkeypatch):
    """A Python thread keeps running while the compiled chunk runs (a sweep's thread executor relies on
    it): one chunk of the whole 3-s run, heartbeats counted inside."""
    _needs_modules()
    monkeypatch.setenv("TELEOP_NO_AOT", "0")
    monkeypatch.setattr(mujoco_loop, "MUJOCO_CHUNK", 10 ** 9)
    aot.forget()
    simulate(Scenario(duration=0.05), progress=False)  # built and loaded before timing
    real = mujoco_loop.A
    calls: list[tuple[float, float]] = []

    class Timed:
        def __getattr__(self, name):
            fn = getattr(real, name)

            def call(*args):
                t0 = time.perf_counter()
                out = fn(*args)
                calls.append((t0, time.perf_counter()))
                return out

            return call

    monkeypatch.setattr(mujoco_loop, "A", Timed())
    beats: list[float] = []
    stop = threading.Event()

    def heartbeat():
        while not stop.is_set():
            beats.append(time.perf_counter())
            time.sleep(0.001)

    th = threading.Thread(target=heartbeat, daemon=True)
    th.start()
    try:
        tr = simulate(Scenario(duration=3.0), progress=False)
    finally:
        stop.set()
        th.join()
        aot.forget()
    assert tr.status == "ok"
    t0, t1 = max(calls, key=lambda c: c[1] - c[0])
    assert t1 - t0 > 0.05  # one long native call
    inside = [b for b in beats if t0 + 0.01 < b < t1 - 0.01]
    assert len(inside) >= 5, (t1 - t0, len(inside))


def test_build_failure_falls_back_to_jit(tmp_path, monkeypatch, caplog, traj_arrays):
    """A module that cannot be built (no C compiler, ...): the run uses the jitted kernel with the same
    numbers, says why once, and records the reason so that later processes do not retry."""
    if os.environ.get("TELEOP_NO_JIT") == "1":
        pytest.skip("interpreted kernels requested (TELEOP_NO_JIT=1)")
    scn = Scenario(duration=0.2)
    ref = _run(scn, True, monkeypatch)
    monkeypatch.setenv("TELEOP_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("TELEOP_NO_AOT", "0")

    def no_compiler(*args, **kwargs):
        raise RuntimeError("no C compiler here")

    monkeypatch.setattr(aot, "build", no_compiler)
    monkeypatch.setattr(aot, "toolchain_problem", lambda: None)  # the build itself fails, toolchain or not
    aot.forget()
    with caplog.at_level(logging.WARNING, logger="harness.loop.aot"):
        tr = simulate(scn, progress=False)
    assert tr.status == "ok"
    for k, v in traj_arrays(ref).items():
        assert np.array_equal(v, getattr(tr, k), equal_nan=True), k
    failed = sorted(aot.aot_dir().glob("*.failed"))
    assert failed and all("no C compiler here" in f.read_text() for f in failed)
    assert "no C compiler here" in caplog.text and "using the jitted kernel" in caplog.text

    def must_not_build(*args, **kwargs):
        raise AssertionError("retried a build that failed before")

    monkeypatch.setattr(aot, "build", must_not_build)
    aot.forget()
    assert simulate(scn, progress=False).status == "ok"
    aot.forget()


@pytest.mark.slow
def test_concurrent_builds_compile_once(tmp_path):
    """Two processes needing the same missing module (two sweep workers) build it once, under the lock,
    and both run it (the smallest entry, backbone_world, in an empty cache)."""
    _needs_modules()
    code = ("import numpy as np; from harness.loop.aot import A; "
            "q2 = np.tile([0.3, 0.3, 0.3, 1.0, -0.5, 0.2], (3, 1)); out = np.zeros((3, 13, 3)); "
            "A.backbone_world(q2, 4, np.array([1.5, 0.0, 0.0]), out); print(float(out.sum()))")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TELEOP_NO_AOT": "0", "TELEOP_CACHE_DIR": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=env, cwd=ROOT) for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1] for o in outs]
    assert outs[0][0] == outs[1][0] and float(outs[0][0]) != 0.0
    notices = sum(o[1].count("compiling the loop kernel backbone_world") for o in outs)
    assert notices == 1, [o[1] for o in outs]
    assert len(list(tmp_path.glob("aot-*/octarm_backbone_world_*.so"))) == 1


def test_entries_are_declared():
    with pytest.raises(AttributeError, match="ENTRIES"):
        aot.A.control_step  # noqa: B018 - per-step kernels stay jitted


def test_forget_rereads_the_environment(monkeypatch):
    monkeypatch.setenv("TELEOP_NO_AOT", "1")
    aot.forget()
    simulate(Scenario(duration=0.02), progress=False)
    fns = [fn for e in aot.A._entries.values() for fn in e._fns.values()]  # noqa: SLF001
    aot.forget()
    assert fns and not any(_from_built_module(fn) for fn in fns)


def test_no_c_compiler_falls_back_without_compiling(tmp_path, monkeypatch, caplog):
    """Without a C compiler nothing is compiled for a module that could not be linked: the reason is
    recorded at once and the jitted kernel runs."""
    if os.environ.get("TELEOP_NO_JIT") == "1":
        pytest.skip("interpreted kernels requested (TELEOP_NO_JIT=1)")
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setenv("TELEOP_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("TELEOP_NO_AOT", "0")

    def must_not_build(*args, **kwargs):
        raise AssertionError("tried to build without a compiler")

    monkeypatch.setattr(aot, "build", must_not_build)
    aot.forget()
    with caplog.at_level(logging.WARNING, logger="harness.loop.aot"):
        assert simulate(Scenario(duration=0.05), progress=False).status == "ok"
    aot.forget()
    failed = sorted(aot.aot_dir().glob("*.failed"))
    assert failed and all("no C compiler" in f.read_text() for f in failed)
    assert "no C compiler" in caplog.text
