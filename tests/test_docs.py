"""The docs: the site builds with `mkdocs build --strict` (slow tier), the generated file references
list every field of the code's schema, and the README stays a short guide with no development history."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from harness.config import reference

ROOT = Path(__file__).resolve().parents[1]


def _hook():
    path = ROOT / "docs" / "hooks" / "reference.py"
    spec = importlib.util.spec_from_file_location("docs_reference_hook", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_reference_pages_carry_the_generation_marker():
    hook = _hook()
    for kind in hook.KINDS:
        page = (ROOT / "docs" / "reference" / f"{kind}.md").read_text()
        assert hook.MARKER.search(page).group(1) == kind
        assert hook.reference_markdown(kind) == reference.markdown(kind)  # the one generator


def test_readme_is_a_short_guide():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 300
    first_block = re.search(r"```bash\n(.*?)```", text, re.S).group(1).strip().splitlines()
    assert first_block == [
        'python3 -m venv .venv && .venv/bin/pip install -e ".[test]" '
        "&& .venv/bin/teleop run --out runs/paper",
        '.venv/bin/python -m pytest -m "slow or not slow"',
    ]
    ci = (ROOT / ".ci" / "run").read_text()  # CI installs and tests the way the README says
    assert '.venv/bin/pip install -q -e ".[test]"' in ci and first_block[1] in ci
    for pattern in (r"\bissue \d+", r"\b\d{4}-\d\d-\d\d \d\d:\d\d", r"\bround\b", r"\b[0-9a-f]{7}\b"):
        assert not re.search(pattern, text), pattern


@pytest.mark.slow
def test_mkdocs_build_strict(tmp_path):
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600,
                         env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert res.returncode == 0, res.stdout + res.stderr
    api = (tmp_path / "site" / "reference" / "api" / "index.html").read_text()
    assert "load_scenario" in api and "Observation" in api  # the docstrings were rendered
    findings = (tmp_path / "site" / "findings" / "index.html").read_text()
    assert "eq28_sign_typo" in findings  # the generated findings table was included


@pytest.mark.slow
def test_the_controller_example_of_the_guide_runs_on_the_default_plant(tmp_path):
    page = (ROOT / "docs" / "guide" / "controllers.md").read_text()
    code = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    (tmp_path / "my_controller.py").write_text(code)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "harness.cli", "run", "--controller", "my_controller.py:TipPD",
           "--duration", "2", "--no-progress", "--out", "out"]
    res = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "status ok" in res.stdout


CODE_REF = re.compile(r"`((?:controllers|harness)/[a-z_/]+\.py)`: ((?:`[A-Za-z_]\w*`(?:, | and )?)+)")


def test_docs_name_code_that_exists():
    """Every "`module.py`: `name`, ..." reference in the docs names a file and a top-level definition
    (or a class attribute) that exist, so a renamed or removed function cannot stay documented."""
    import ast

    root = Path(__file__).resolve().parents[1]
    missing = []
    for doc in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
        for path, names in CODE_REF.findall(doc.read_text(encoding="utf-8")):
            src = root / path
            if not src.is_file():
                missing.append(f"{doc.name}: {path}")
                continue
            defined = {n.name for n in ast.walk(ast.parse(src.read_text(encoding="utf-8")))
                       if isinstance(n, ast.FunctionDef | ast.ClassDef)}
            defined |= {t.id for n in ast.parse(src.read_text(encoding="utf-8")).body
                        if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)}
            missing += [f"{doc.name}: {path}: {n}" for n in re.findall(r"`(\w+)`", names) if n not in defined]
        text = doc.read_text(encoding="utf-8")
        for path in re.findall(r"`((?:controllers|harness|tests|benchmarks|examples)/[\w/]+\.py)", text):
            if not (root / path).is_file():
                missing.append(f"{doc.name}: {path}")
    assert not missing, f"docs name code that does not exist: {missing}"
