"""Each benchmark script owns one section of a shared results file (benchmarks/RESULTS*.md), between its own
markers, and rewrites only that section: the other scripts' tables and the hand-written analyses in the same
file are kept (bench_loop.py once overwrote the whole of RESULTS.md, bench_cosserat.py the whole of
RESULTS_cosserat.md)."""

from __future__ import annotations

from pathlib import Path


def markers(owner: str) -> tuple[str, str]:
    """The begin and end markers of `owner`'s section (an HTML comment: invisible in rendered markdown)."""
    return f"<!-- {owner}: begin -->", f"<!-- {owner}: end -->"


def replace_section(text: str, section: str, owner: str) -> str:
    """`text` with `owner`'s section (between its markers) replaced by `section`; without the markers, the
    section goes first and the rest of `text` stays below it."""
    begin, end = markers(owner)
    block = f"{begin}\n{section.rstrip()}\n{end}\n"
    if begin in text and end in text.split(begin, 1)[1]:
        head, rest = text.split(begin, 1)
        after = rest.split(end, 1)[1].lstrip("\n")
        return head + block + ("\n" + after if after else "")
    return block + ("\n" + text if text.strip() else "")


def write_section(path: Path, section: str, owner: str) -> None:
    """Replace `owner`'s section of the file at `path` (created if missing)."""
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    path.write_text(replace_section(old, section, owner), encoding="utf-8")
