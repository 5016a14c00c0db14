"""The shipped files: `mjcf/`, `scenarios/`, `bounds/`, `studies/`, `findings/` of the checkout.

They stay at the top of the checkout (the customer's layout) and are installed as package data
`harness._data.<kind>` (pyproject.toml maps each folder there with `package-dir`), so that a wheel
(non-editable) install finds them inside the package.  `asset_dir(kind)` locates them with the
import system (`importlib.util.find_spec`: regular install, editable install) and falls back to the
checkout folder when the harness is imported from a checkout (`PYTHONPATH=checkout`).

`shipped(path, kind)` lets every command name a shipped file from any folder: a path that does not
exist and is a bare name (`paper_mujoco`, `paper_mujoco.toml`) or `<kind>/<name>` resolves to the
shipped file of that name; anything else is returned unchanged (and reported as not found later).
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

KINDS = ("mjcf", "scenarios", "bounds", "studies", "findings")
_CHECKOUT = Path(__file__).resolve().parents[2]


@cache
def asset_dir(kind: str) -> Path:
    """Folder of the shipped `kind` files (one of KINDS)."""
    if kind not in KINDS:
        raise ValueError(f"unknown asset kind {kind!r}; one of {KINDS}")
    try:
        spec = importlib.util.find_spec(f"harness._data.{kind}")
    except ModuleNotFoundError:
        spec = None
    for loc in (spec.submodule_search_locations or []) if spec is not None else []:
        if Path(loc).is_dir():
            return Path(loc)
    return _CHECKOUT / kind


def shipped(path: str | Path, kind: str) -> Path:
    """`path` itself if it exists, else the shipped file it names (see the module docstring)."""
    path = Path(path)
    if path.exists() or path.is_absolute():
        return path
    parts = path.parts
    if len(parts) == 1 or (len(parts) == 2 and parts[0] == kind):
        name = parts[-1] if Path(parts[-1]).suffix else parts[-1] + (".xml" if kind == "mjcf" else ".toml")
        candidate = asset_dir(kind) / name
        if candidate.is_file():
            return candidate
    return path


__all__ = ["KINDS", "asset_dir", "shipped"]
