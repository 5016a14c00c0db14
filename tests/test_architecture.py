"""The layout is the architecture: no import cycles in harness/, and each subpackage depends only on the
layers below it (config <- plant <- loop <- output <- studies <- api/cli).  Imports are read from the
source with `ast` (module level and inside functions alike), so a lazy import counts too."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HARNESS = ROOT / "harness"

# What each part of harness/ may import (besides itself, controllers/ and third-party packages).
ALLOWED = {
    "config": set(),
    "plant": {"config"},
    "loop": {"config", "plant"},
    "output": {"config", "loop"},
    "studies": {"config", "plant", "loop", "output"},
    "api": {"config", "plant", "loop", "output", "studies"},
    "cli": {"config", "api", "plant", "loop", "output", "studies"},
    "__init__": {"api", "loop"},
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(HARNESS.rglob("*.py"))}


def _imports(path: Path, name: str, known: set[str]) -> set[str]:
    """harness modules imported by the file (the deepest known module of each imported name)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = name if is_pkg else name.rsplit(".", 1)[0]
                for _ in range(node.level - 1):
                    pkg = pkg.rsplit(".", 1)[0]
                base = f"{pkg}.{base}" if base else pkg
            # `from pkg import sub` imports the submodule; `from pkg import name` the package itself
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        for t in targets:
            while t and t not in known:
                t = t.rsplit(".", 1)[0] if "." in t else ""
            if t and t != name:
                out.add(t)
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(path, name, known) for name, path in mods.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def _part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_graph_sees_the_imports():
    """The checker itself: it finds known edges (else the tests below would pass vacuously)."""
    g = _graph()
    assert "harness.loop.mujoco_loop" in g and "harness.plant.mujoco_model" in g["harness.loop.mujoco_loop"]
    assert "harness.config.scenario" in g["harness.config.load"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles_in_harness():
    cycles = _cycles(_graph())
    assert not cycles, f"import cycles in harness/: {cycles}"


@pytest.mark.parametrize("part", sorted(ALLOWED))
def test_layers(part):
    bad = []
    for mod, deps in _graph().items():
        if _part(mod) != part:
            continue
        for d in deps:
            if _part(d) != part and _part(d) not in ALLOWED[part]:
                bad.append(f"{mod} -> {d}")
    assert not bad, f"harness/{part} imports what it must not: {bad}"


def test_every_module_belongs_to_a_known_part():
    assert {_part(m) for m in _modules()} <= set(ALLOWED)


def test_modules_stay_small():
    """No module over ~500 lines (the design card); 550 is the hard limit here."""
    big = {str(p.relative_to(ROOT)): n for p in HARNESS.rglob("*.py")
           if (n := len(p.read_text(encoding="utf-8").splitlines())) > 550}
    assert not big, f"modules over 550 lines: {big}"
