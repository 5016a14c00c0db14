"""The two test tiers: plain `pytest` selects the fast tier only, the README's test command (which CI runs)
selects both, `-m slow` the slow one."""

from __future__ import annotations

import re
import shlex
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _mark_expr(args: list[str]) -> str | None:
    """The last -m expression of a pytest command line (a later -m replaces an earlier one)."""
    expr = None
    for i, a in enumerate(args):
        if a == "-m" and i + 1 < len(args):
            expr = args[i + 1]
        elif a.startswith("-m") and len(a) > 2:
            expr = a[2:]
    return expr


def _selects(expr: str | None, slow: bool) -> bool:
    """Whether a test with (slow=True) or without (slow=False) the marker is selected: pytest's marker
    expressions (and, or, not, parentheses, names) are Python expressions over the marker names."""
    if expr is None:
        return True
    assert re.fullmatch(r"[\w\s()]+", expr), expr
    return bool(eval(expr, {"__builtins__": {}}, {"slow": slow}))  # noqa: S307 - checked above


def _readme_test_command() -> list[str]:
    block = re.search(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    line = next(x for x in block.strip().splitlines() if " -m pytest" in x)
    return shlex.split(line)


def test_plain_pytest_is_the_fast_tier():
    opts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    expr = _mark_expr(shlex.split(opts["addopts"]))
    assert _selects(expr, slow=False) and not _selects(expr, slow=True)
    assert any(m.startswith("slow:") for m in opts["markers"])


def test_readme_command_runs_both_tiers_and_ci_runs_it():
    cmd = _readme_test_command()
    expr = _mark_expr(cmd)
    assert _selects(expr, slow=False) and _selects(expr, slow=True)
    ci = [shlex.split(x.split("#")[0]) for x in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert cmd in ci, "CI runs the README's test command"


def test_readme_says_how_to_run_one_tier():
    text = (ROOT / "README.md").read_text()
    tests = text[text.index("**Tests.**"):]
    assert "`.venv/bin/python -m pytest` runs only the fast tier" in tests and "`-m slow`" in tests
