"""MkDocs hook: the file-reference pages (scenario, bounds, study) are generated from the code's
schema when the docs are built, so that they cannot drift from it.

A page opts in with a marker line ``<!-- generated-reference: KIND -->`` (KIND = scenario, bounds or
study); the hook replaces everything after the marker with `reference_markdown(KIND)`.

`reference_markdown` is ``harness.config.reference.markdown(KIND)``, the one generator.
"""

from __future__ import annotations

import re

MARKER = re.compile(r"<!--\s*generated-reference:\s*(\w+)\s*-->")
KINDS = ("scenario", "bounds", "study")


def reference_markdown(kind: str) -> str:
    """The generated reference of one file kind (markdown)."""
    from harness.config.reference import markdown

    return markdown(kind)


def on_page_markdown(markdown: str, page, config, files):  # noqa: ARG001 (MkDocs hook signature)
    m = MARKER.search(markdown)
    if not m:
        return markdown
    kind = m.group(1)
    if kind not in KINDS:
        raise ValueError(f"{page.file.src_uri}: unknown generated-reference kind {kind!r}")
    return markdown[: m.end()] + "\n\n" + reference_markdown(kind) + "\n"
