"""Outputs of the robustness margins (`harness.studies.margin`): the table, the bars around the nominal
point and the 2-D edge figure."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

from harness.studies.figures import pyplot, save_figure
from harness.studies.margin import Margin, param_of


def plot_edge(rows: list[dict], pair: tuple[str, str], path) -> Path:
    fig, ax = pyplot().subplots(figsize=(4.6, 4.2))
    closed = [*rows, rows[0]]
    ax.plot([r["p1"] for r in closed], [r["p2"] for r in closed], "g.-", label="last passing point")
    fails = [r for r in rows if r["fail_p1"] is not None]
    ax.plot([r["fail_p1"] for r in fails], [r["fail_p2"] for r in fails], "rx", label="first failing point")
    ax.plot([1], [1], "ko", label="nominal")
    ax.set(xscale="log", yscale="log", xlabel=f"{pair[0]} (x nominal)", ylabel=f"{pair[1]} (x nominal)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)


def _edge_metric(d: dict) -> str:
    """'metric: at the margin -> at the first failing point' (the run's status when not measured)."""
    if d.get("fail") is None:
        return "-"
    at_fail = d.get("metric_at_fail")
    fail = _fmt(at_fail) if at_fail is not None else f"not measured ({d.get('status_at_fail')})"
    return f"{d.get('bound_metric')}: {_fmt(d.get('metric_at_margin'))} -> {fail}"


def margins_markdown(rows: Sequence[Margin], tol_text: str = "") -> str:
    lines = ["| parameter | nominal | lower margin | upper margin | first bound to fail (lower / upper) | "
             "metric at the edge (lower / upper: margin -> fail) |", "|---|---:|---:|---:|---|---|"]
    for r in rows:
        if r.note:
            lines.append(f"| {r.param} | {_fmt(r.nominal)} | n/a | n/a | {r.note} | |")
            continue
        cells = []
        for side in ("lower", "upper"):
            d = r.sides.get(side, {})
            m = _fmt(d.get("margin"))
            if d.get("range_end"):
                m += " (range end, passes)"
            if d.get("non_monotone"):
                m += f" (non-monotone: fails at {', '.join(_fmt(x) for x in d['non_monotone'])})"
            cells.append(m)
        fb = " / ".join(r.sides.get(s, {}).get("first_bound") or "-" for s in ("lower", "upper"))
        me = " / ".join(_edge_metric(r.sides.get(s, {})) for s in ("lower", "upper"))
        lines.append(f"| {r.param} | {_fmt(r.nominal)} | {cells[0]} | {cells[1]} | {fb} | {me} |")
    if tol_text:
        lines += ["", tol_text]
    return "\n".join(lines)


def plot_margins(rows: Sequence[Margin], path) -> Path:
    """Margins as bars around the nominal point: one row per parameter, log axis for scale factors."""
    rows = [r for r in rows if not r.note]
    fig, axes = pyplot().subplots(len(rows), 1, figsize=(6.5, 0.9 + 0.75 * len(rows)), squeeze=False)
    for ax, r in zip(axes[:, 0], rows, strict=True):
        p = param_of(r.param)
        lo, hi = r.sides["lower"]["margin"], r.sides["upper"]["margin"]
        ax.barh([0], [hi - lo], left=[lo], height=0.5, color="tab:green", alpha=0.6)
        fails = [f for f in (r.sides[side].get("fail") for side in ("lower", "upper")) if f is not None]
        ax.plot(fails, [0] * len(fails), "x", color="tab:red")
        ax.axvline(r.nominal, color="k", lw=1)
        if p.mode in ("scale", "rate"):
            ax.set_xscale("log")
        ax.set_xlim(p.lo, p.hi)
        ax.set_yticks([0], [f"{r.param} ({p.unit})" if p.unit else r.param], fontsize=8)
        ax.tick_params(axis="x", labelsize=7)
    axes[0, 0].set_title("passing range (green), first failing level (x), nominal (line)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def write_margins(rows: Sequence[Margin], out, tol_text: str = "") -> list[Path]:
    """margins.md, margins.json and margins.png in folder `out` (atomic renames)."""
    import json

    from harness.config.textio import jsonable, write_atomic

    out = Path(out)
    paths = [write_atomic(out / "margins.md", margins_markdown(rows, tol_text) + "\n"),
             write_atomic(out / "margins.json", json.dumps(jsonable([dataclasses.asdict(r) for r in rows]),
                                                          indent=2) + "\n")]
    if any(not r.note for r in rows):
        paths.append(plot_margins(rows, out / "margins.png"))
    return paths


__all__ = ["margins_markdown", "plot_edge", "plot_margins", "write_margins"]
