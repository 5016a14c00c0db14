"""Packaging: the shipped MJCF, scenarios, bounds and studies are package data, every
package is in the wheel, and a NON-editable install runs `teleop run` from any folder.

The wheel test builds a wheel from a copy of the source tree (`pip wheel`, once per session) and
installs it with `--no-deps` into a new venv whose dependencies come from this interpreter's
site-packages through a plain `.pth` path line: that path line does not execute the site's own
`.pth` files, so the editable install of the checkout there is NOT importable and the harness, its
MJCF and its scenarios can only come from the wheel (the test checks where they were imported from).
`.ci/run` does the fully fresh install (dependencies from the registry).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

import pytest

from harness.config.assets import KINDS, asset_dir, shipped
from harness.config.bounds import load_bounds
from harness.config.load import load_scenario

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SHIPPED = KINDS
SOURCES = ("pyproject.toml", "README.md", "harness", "controllers", *SHIPPED)


def test_every_package_and_asset_folder_is_listed():
    st = PYPROJECT["tool"]["setuptools"]
    on_disk = {".".join(p.parent.relative_to(ROOT).parts) for top in ("harness", "controllers")
               for p in (ROOT / top).rglob("__init__.py")}
    data = {f"harness._data.{k}" for k in SHIPPED}
    assert set(st["packages"]) == on_disk | data
    assert st["package-dir"] == {f"harness._data.{k}": k for k in SHIPPED}
    for k in SHIPPED:
        patterns = st["package-data"][f"harness._data.{k}"]
        files = {p.name for p in (ROOT / k).iterdir() if p.is_file()}
        assert files and all(any(Path(f).match(pat) for pat in patterns) for f in files), k


def test_assets_resolve_from_the_checkout_and_by_name(tmp_path, monkeypatch):
    for k in KINDS:
        assert asset_dir(k) == ROOT / k
    monkeypatch.chdir(tmp_path)  # not the checkout: shipped names still resolve
    assert shipped("paper_mujoco", "bounds") == ROOT / "bounds" / "paper_mujoco.toml"
    assert shipped("scenarios/paper.toml", "scenarios") == ROOT / "scenarios" / "paper.toml"
    assert shipped("nope", "bounds") == Path("nope")
    assert load_bounds("paper_mujoco") == load_bounds(ROOT / "bounds" / "paper_mujoco.toml")
    assert load_scenario("paper") == load_scenario(ROOT / "scenarios" / "paper.toml")
    (tmp_path / "paper").write_text('name = "mine"\n')  # an existing file wins over a shipped name
    assert load_scenario("paper").name == "mine"


@pytest.fixture(scope="session")
def wheel(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("src")
    for name in SOURCES:
        p = ROOT / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(p, src / name)
    dist = tmp_path_factory.mktemp("dist")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "-w", str(dist), "--no-deps", "-q"],
                         capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr
    (whl,) = dist.glob("octarm_teleop-*.whl")
    return whl


@pytest.mark.slow
def test_wheel_install_runs_from_any_folder(wheel, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing from the checkout
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    res = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps",
                          "--no-index", str(wheel)], capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, res.stderr
    purelib = "import sysconfig; print(sysconfig.get_path('purelib'))"
    site = Path(subprocess.check_output([str(py), "-c", purelib], text=True, env=env).strip())
    assert (site / "harness" / "_data" / "mjcf" / "scene.xml").is_file()
    (site / "zz_deps.pth").write_text(sysconfig.get_path("purelib") + "\n")  # dependencies only
    work = tmp_path / "elsewhere"
    work.mkdir()
    where = subprocess.run(
        [str(py), "-c", "import harness, harness.plant.mujoco_model as m; print(harness.__file__); "
                        "print(m.SCENE_XML)"], cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert where.returncode == 0, where.stderr
    for line in where.stdout.split():
        assert Path(line).is_relative_to(site), line  # the wheel's own code and MJCF
    probe = ("from harness.config.assets import shipped; from harness.config.bounds import load_bounds; "
             "from harness.config.load import load_scenario; load_bounds('paper_mujoco'); "
             "print(load_scenario('paper').name); print(shipped('paper_mujoco', 'bounds')); "
             "print(shipped('studies/segments.toml', 'studies')); "
             "from harness.studies.findings import load_finding; print(load_finding('eq28_sign_typo').path)")
    names = subprocess.run([str(py), "-c", probe], cwd=work, env=env, capture_output=True, text=True,
                           timeout=300)
    assert names.returncode == 0, names.stderr
    name, *paths = names.stdout.split()
    assert name == "paper" and all(Path(p).is_relative_to(site) and Path(p).is_file() for p in paths)
    # interpreted kernels (TELEOP_NO_JIT=1, same maths): this test is about the installed files; numba
    # would recompile every kernel for the new install path (~3 min).  .ci/run runs the compiled main job
    # from a wheel in a fresh venv.
    run = subprocess.run([str(venv / "bin" / "teleop"), "run", "--duration", "1", "--out", "o",
                          "--no-progress"], cwd=work, env={**env, "TELEOP_NO_JIT": "1"},
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert (work / "o" / "run.rrd").stat().st_size > 0
    # provenance from the wheel: its version, no git revision (not a checkout), never an error
    tool = json.loads((work / "o" / "metrics.json").read_text())["tool"]
    assert tool == {"name": "octarm-teleop", "version": wheel.name.split("-")[1]}
