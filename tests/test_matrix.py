"""Every plant x actuation x controller, briefly (Menagerie style).

Each cell loads the paper scenario with the plant, actuation and controller set, for DURATION seconds of
simulated time.  It either runs to the end with status ok, every array of the trajectory finite and no
MuJoCo warning, or `load_scenario` refuses it before anything runs with a one-line ConfigError (a
requirement the controller or the schema declares).  Anything else (a traceback, a diverged or
non-finite run, a warning) is a failing cell.

The axes come from the code, so a new one is picked up without editing this file: the plant kinds and
actuations from the scenario schema (`harness.config.scenario.PLANTS`, `ACTUATIONS`; the MuJoCo plant
twice, free chain and `plant.enforce_cc = true`), the controllers from the registry of built-ins
(`controllers.baselines.BUILTINS`) plus every controller class in `examples/controllers/*.py`.

The outcome table is kept in docs/matrix.md; `test_matrix` checks that the committed page equals what
the code produces now.  Regenerate it (and print it) with

    PYTHONPATH=. python tests/test_matrix.py --write
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "matrix.md"
EXAMPLES = ROOT / "examples" / "controllers"
DURATION = 0.2  # s of simulated time per cell

# Cells that fail today because of a bug outside the tests, each with the bug in one line.  The test
# demands that these cells still fail (strict: remove the entry once the bug is fixed) and that every
# other cell passes; the table marks them.
KNOWN_BUGS: dict[tuple[str, str, str], str] = {}


def plants() -> list[tuple[str, list[str]]]:
    """(label, overrides) of every plant: each kind of the schema, the MuJoCo one as free and CC chain."""
    from harness.config.scenario import PLANTS

    out = []
    for kind in PLANTS:
        if kind == "mujoco":
            out.append(("mujoco free chain", ["plant.kind='mujoco'", "plant.enforce_cc=false"]))
            out.append(("mujoco CC chain", ["plant.kind='mujoco'", "plant.enforce_cc=true"]))
        else:
            out.append((kind, [f"plant.kind={kind!r}"]))
    return out


def actuations() -> tuple[str, ...]:
    from harness.config.scenario import ACTUATIONS

    return tuple(ACTUATIONS)


def example_controllers() -> list[str]:
    """'examples/controllers/<file>.py:<Class>' of every controller class there (a subclass of
    `Controller` or a class with a `step` method)."""
    names = []
    for path in sorted(EXAMPLES.glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef):
                methods = {f.name for f in node.body if isinstance(f, ast.FunctionDef)}
                bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                if "step" in methods or "Controller" in bases:
                    names.append(f"{path.relative_to(ROOT).as_posix()}:{node.name}")
    return names


def controllers() -> list[str]:
    from controllers.baselines import BUILTINS

    return list(BUILTINS) + example_controllers()


def run_cell(plant_overrides: list[str], actuation: str, controller: str) -> tuple[str, str]:
    """("ok" | "refused" | "FAILS", detail) of one cell."""
    from harness.api import load_scenario
    from harness.config.errors import ConfigError
    from harness.loop import simulate

    name = str(ROOT / controller) if controller.startswith("examples/") else controller
    overrides = [f"duration={DURATION}", "seed=0", *plant_overrides, f"plant.actuation={actuation!r}",
                 f"controller.name={name!r}"]
    try:
        scn = load_scenario(None, overrides)
    except ConfigError as e:
        return "refused", str(e).replace(str(ROOT) + "/", "")
    try:
        traj = simulate(scn)
    except Exception as e:  # noqa: BLE001 - a traceback is a failing cell, reported in the table
        return "FAILS", f"raised {type(e).__name__}: {' '.join(str(e).split())[:160]}"
    bad = [k for k, v in vars(traj).items()
           if isinstance(v, np.ndarray) and v.dtype.kind == "f" and not np.isfinite(v).all()]
    warnings = int(traj.meta.get("mujoco_warnings", 0))
    steps = scn.n_steps
    if traj.status != "ok":
        return "FAILS", f"{traj.status}: {traj.message}"
    if bad:
        return "FAILS", f"non-finite {', '.join(bad)}"
    if warnings:
        return "FAILS", f"{warnings} MuJoCo warnings {traj.meta.get('mujoco_warning_counts')}"
    if len(traj.t) < steps:
        return "FAILS", f"{len(traj.t)} of {steps} steps"
    return "ok", ""


def outcomes() -> dict[tuple[str, str, str], tuple[str, str]]:
    return {(label, act, ctrl): run_cell(ov, act, ctrl)
            for ctrl in controllers() for label, ov in plants() for act in actuations()}


def render(res: dict[tuple[str, str, str], tuple[str, str]]) -> str:
    """docs/matrix.md: the grid (one row per controller, one column per plant x actuation) and the
    refusals and failures, numbered, one line each."""
    cols = [(label, act) for label, _ in plants() for act in actuations()]
    notes: list[str] = []

    def mark(kind: str, detail: str, key) -> str:
        if kind == "ok":
            return "runs"
        text = detail if kind == "refused" else f"{detail} (known bug: {KNOWN_BUGS[key]})" \
            if key in KNOWN_BUGS else detail
        if text not in notes:
            notes.append(text)
        n = notes.index(text) + 1
        return f"refused [{n}]" if kind == "refused" else f"**FAILS** [{n}]"

    lines = [
        "# Controller x plant matrix",
        "",
        "Every controller (the built-ins and `examples/controllers/`) on every plant and actuation, "
        f"{DURATION} s of the paper scenario (seed 0). *runs*: status ok, every array finite, no MuJoCo "
        "warning. *refused*: the harness declined the combination before anything ran, with the one-line "
        "reason below. Generated by `tests/test_matrix.py` (`PYTHONPATH=. python tests/test_matrix.py "
        "--write`); the test fails when this page differs from what the code produces.",
        "",
        "| controller | " + " | ".join(f"{label} / {act}" for label, act in cols) + " |",
        "| --- |" + " --- |" * len(cols),
    ]
    for ctrl in controllers():
        cells = [mark(*res[(label, act, ctrl)], (label, act, ctrl)) for label, act in cols]
        lines.append(f"| `{ctrl}` | " + " | ".join(cells) + " |")
    lines += ["", "Reasons:", ""]
    lines += [f"{i}. {text}" for i, text in enumerate(notes, 1)]
    return "\n".join(lines) + "\n"


def test_matrix():
    res = outcomes()
    page = render(res)
    print("\n" + page)
    for key, (kind, detail) in res.items():
        if kind == "refused":
            assert detail and "\n" not in detail and "Traceback" not in detail, (key, detail)
    failing = {k: d for k, (kind, d) in res.items() if kind == "FAILS"}
    unexpected = {k: d for k, d in failing.items() if k not in KNOWN_BUGS}
    fixed = [k for k in KNOWN_BUGS if k not in failing]
    assert not unexpected, f"failing cells: {unexpected}"
    assert not fixed, f"these cells pass now: remove them from KNOWN_BUGS: {fixed}"
    assert PAGE.read_text() == page, "docs/matrix.md is stale: regenerate it (see this module's docstring)"


def test_axes_come_from_the_code():
    """The axes are the schema's and the registry's: nothing hand-listed that could fall behind."""
    from controllers.baselines import BUILTINS
    from harness.config.scenario import ACTUATIONS, PLANTS

    assert actuations() == tuple(ACTUATIONS)
    assert {ov[0] for _, ov in plants()} == {f"plant.kind={k!r}" for k in PLANTS}
    names = controllers()
    assert set(BUILTINS) <= set(names)
    files = {n.split(":")[0] for n in example_controllers()}
    assert files == {p.relative_to(ROOT).as_posix() for p in EXAMPLES.glob("*.py")}  # one class or more each


if __name__ == "__main__":
    text = render(outcomes())
    print(text)
    if "--write" in sys.argv[1:]:
        PAGE.write_text(text)
        print(f"wrote {PAGE.relative_to(ROOT)}")
