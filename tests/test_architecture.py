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
        elif (dyn := _dynamic_import(node)) is not None and isinstance(dyn, str):
            targets = [dyn]  # a module imported by its name, as a string literal: the same rules apply
        for t in targets:
            while t and t not in known:
                t = t.rsplit(".", 1)[0] if "." in t else ""
            if t and t != name:
                out.add(t)
    return out


DYNAMIC = ("import_module", "__import__", "_import", "spec_from_file_location", "exec_module")


def _dynamic_import(node: ast.AST):
    """For a call that imports a module by name (importlib.import_module, __import__, the CLI's lazy
    `_import`, spec_from_file_location / exec_module): the module name if it is a string literal, else the
    call node; None for any other node."""
    if not isinstance(node, ast.Call):
        return None
    f = node.func
    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None
    if name not in DYNAMIC:
        return None
    if node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str) \
            and name != "spec_from_file_location":
        return node.args[0].value
    return node


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


@pytest.mark.slow
def test_graph_sees_the_imports():
    """The checker itself: it finds known edges (else the tests below would pass vacuously)."""
    g = _graph()
    assert "harness.loop.mujoco_loop" in g and "harness.plant.mujoco_model" in g["harness.loop.mujoco_loop"]
    assert "harness.config.scenario" in g["harness.config.load"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.slow
def test_no_import_cycles_in_harness():
    cycles = _cycles(_graph())
    assert not cycles, f"import cycles in harness/: {cycles}"


@pytest.mark.slow
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


# Modules that import by a name computed at run time, and why that is no way around the layer rules.
DYNAMIC_ALLOWED = {
    "harness.config.controller": "the user-controller loader (file.py:Class, module:Class)",
    "harness.loop.aot": "loads its compiled extension modules from the kernel cache (not project code)",
    "harness.studies.executor": "imports WARM_MODULES (a literal tuple of harness modules, checked below)",
}


@pytest.mark.slow
def test_no_module_imports_by_a_computed_name():
    """A module named by a string literal counts as an import (layer rules above); a name computed at run
    time is only allowed where DYNAMIC_ALLOWED says why."""
    bad = []
    for name, path in _modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            dyn = _dynamic_import(node)
            if dyn is not None and not isinstance(dyn, str) and name not in DYNAMIC_ALLOWED:
                bad.append(f"{name}:{node.lineno}")
    for path in sorted((ROOT / "controllers").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if _dynamic_import(node) is not None:
                bad.append(f"controllers/{path.name}:{node.lineno}")
    assert not bad, f"imports by a computed name: {bad}"


@pytest.mark.slow
def test_the_dynamic_import_checker_sees_them():
    call = ast.parse("importlib.import_module(name)").body[0].value
    assert _dynamic_import(call) is call
    assert _dynamic_import(ast.parse("_import('harness.api')").body[0].value) == "harness.api"
    assert "harness.studies.sweep" in _graph()["harness.cli"]


def test_warm_modules_keep_the_layer_rules():
    from harness.studies.executor import WARM_MODULES

    known = set(_modules())
    for mod in WARM_MODULES:
        assert mod in known, mod
        assert _part(mod) in ALLOWED["studies"] | {"studies"}, mod


# ----------------------------------------------------------------------------- no dead production code
# Production functions used only by tests, each with its owner's reason; everything else a test alone
# uses is dead code (the test below).  Entries are independent references or entry points of modules
# whose consolidation is under way elsewhere (the slave and master models, the Cosserat rod, outputs).
TEST_ONLY = {
    "to_file", "slave_control",
    "read_series",  # the users' reader of a run.rrd series (docs/guide/outputs.md)
    "forget",  # aot: the test hook that makes a process resolve its entry modules anew (TELEOP_NO_AOT, cache)
}


def _production_defs() -> dict[str, list[Path]]:
    """Top-level functions and classes and the methods of classes in controllers/ and harness/."""
    out: dict[str, list[Path]] = {}
    for p in sorted([*(ROOT / "controllers").rglob("*.py"), *HARNESS.rglob("*.py")]):
        for node in ast.parse(p.read_text(encoding="utf-8")).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                out.setdefault(node.name, []).append(p)
            if isinstance(node, ast.ClassDef):
                for sub in node.body:
                    if isinstance(sub, ast.FunctionDef) and not sub.name.startswith("__"):
                        out.setdefault(sub.name, []).append(p)
    return out


def _names_used(paths) -> set[str]:
    """Every name, attribute, imported name and string constant in the files (a kernel is named in its
    module's KERNELS tuple; a registry maps strings to functions)."""
    used: set[str] = set()
    for p in paths:
        tree = ast.parse(p.read_text(encoding="utf-8"))
        for node in tree.body:  # a name listed in __all__ is exported, not used
            if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets):
                node.value = ast.Constant(None)
        for node in ast.walk(tree):
            if isinstance(node, ast.Name):
                used.add(node.id)
            elif isinstance(node, ast.Attribute):
                used.add(node.attr)
            elif isinstance(node, ast.alias):
                used.add(node.name.rsplit(".", 1)[-1])
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                used.add(node.value)
    return used


@pytest.mark.slow
def test_no_production_function_is_used_only_by_tests():
    """Every function, class and method of controllers/ and harness/ is used by production code (the
    packages themselves, benchmarks, examples); module hooks (__getattr__) aside."""
    users = [*(ROOT / "controllers").rglob("*.py"), *HARNESS.rglob("*.py"),
             *(ROOT / "benchmarks").glob("*.py"), *(ROOT / "examples").rglob("*.py")]
    used = _names_used(users)
    dead = {name: [str(p.relative_to(ROOT)) for p in ps] for name, ps in _production_defs().items()
            if name not in used and name not in TEST_ONLY and not name.startswith("__")}
    assert not dead, f"production code that nothing but tests uses (delete it, or move it to tests/): {dead}"
    stale = {n for n in TEST_ONLY if n not in _production_defs() or n in used}
    assert not stale, f"TEST_ONLY lists names that are gone or used again: {stale}"
