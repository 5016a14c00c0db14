"""MkDocs hook: the file-reference pages (scenario, bounds, study) are generated from the code's
schema when the docs are built, so that they cannot drift from it.

A page opts in with a marker line ``<!-- generated-reference: KIND -->`` (KIND = scenario, bounds or
study); the hook replaces everything after the marker with `reference_markdown(KIND)`.

`reference_markdown` uses ``harness.config.reference.markdown(KIND)`` when that generator exists, and
otherwise builds the table from the schema objects themselves (`harness.config.schema.schema_paths`
and the default scenario; `harness.config.bounds.NUMERIC_BOUNDS` / `FLAG_BOUNDS`; the study module's
docstring).
"""

from __future__ import annotations

import importlib
import re

MARKER = re.compile(r"<!--\s*generated-reference:\s*(\w+)\s*-->")
KINDS = ("scenario", "bounds", "study")


def _toml(v) -> str:
    """A default value as it is written in a scenario file."""
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(round(v, 12))
    return str(v)


def _default(scn, path: str) -> str:
    obj = scn
    for part in path.split("."):
        if obj is None:
            return "the nominal model's value"  # plant.master.* / plant.slave.* when not set
        if not hasattr(obj, part):
            return ""
        obj = getattr(obj, part)
    if hasattr(obj, "__dataclass_fields__"):
        return "(table)"
    text = _toml(obj.tolist() if hasattr(obj, "tolist") else obj)
    if text == "not set":
        return "not set"
    return f"`{text}`" if len(text) <= 60 else f"`{text[:57]}...`"


def _scenario() -> str:
    from harness.config.load import load_scenario
    from harness.config.schema import schema_paths

    scn = load_scenario(None)
    rows = ["| key | default (paper scenario) |", "|---|---|"]
    rows += [f"| `{p}` | {_default(scn, p)} |" for p in schema_paths()]
    return "\n".join(rows)


def _bounds() -> str:
    from harness.config.bounds import FLAG_BOUNDS, NUMERIC_BOUNDS

    rows = ["| key | metric | relation | unit | meaning |", "|---|---|---|---|---|"]
    for key, (metric, rel, unit, desc) in NUMERIC_BOUNDS.items():
        relation = "measured <= limit" if rel == "max" else "measured >= limit"
        rows.append(f"| `{key}` | `{metric}` | {relation} | {unit} | {desc} |")
    for key, desc in FLAG_BOUNDS.items():
        rows.append(f"| `{key}` | | true / false | | {desc} |")
    return "\n".join(rows)


def _study() -> str:
    import harness.studies.study as study

    return "```text\n" + (study.__doc__ or "").strip() + "\n```"


def reference_markdown(kind: str) -> str:
    """The generated reference of one file kind (markdown)."""
    try:
        gen = importlib.import_module("harness.config.reference")
    except ImportError:
        gen = None
    if gen is not None and hasattr(gen, "markdown"):
        return gen.markdown(kind)
    return {"scenario": _scenario, "bounds": _bounds, "study": _study}[kind]()


def on_page_markdown(markdown: str, page, config, files):  # noqa: ARG001 (MkDocs hook signature)
    m = MARKER.search(markdown)
    if not m:
        return markdown
    kind = m.group(1)
    if kind not in KINDS:
        raise ValueError(f"{page.file.src_uri}: unknown generated-reference kind {kind!r}")
    return markdown[: m.end()] + "\n\n" + reference_markdown(kind) + "\n"
