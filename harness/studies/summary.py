"""Summaries of a sweep: `summary.csv` (one row per case) and the plots (metric vs factor lines,
2-factor heatmaps)."""

from __future__ import annotations

import itertools
import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from harness.studies.figures import save_csv, save_figure
from harness.studies.study import METRIC_LABELS, Case, Study, canon, is_real


def _cell(v: Any) -> Any:
    return "" if v is None else (json.dumps(v) if isinstance(v, list | dict) else v)


def _label(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return json.dumps(v) if isinstance(v, list | dict) else str(v)


def _safe(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name)


def write_summary(study: Study, cases: Sequence[Case], rows: dict[str, dict],
                  out: str | os.PathLike) -> list[Path]:
    """summary.csv (one row per case of the study that has a result) and the plots; returns the paths."""
    out = Path(out)
    done = [rows[c.case_id] for c in cases if c.case_id in rows]
    names = [f.name for f in study.factors]
    head = ["case_id", *names, "status", *study.metrics, "case_wall_time", "message"]
    path = save_csv(out / "summary.csv", [
        [r["case_id"], *(_cell(r["params"].get(n)) for n in names), r["status"],
         *(_cell(r["metrics"].get(m)) for m in study.metrics), _cell(r["wall_time"]), r["message"]]
        for r in done], head)
    return [path, *_plots(study, done, out)]


def _metric_array(rows: Sequence[dict], metric: str) -> np.ndarray:
    return np.array([v if is_real(v := r["metrics"].get(metric)) else np.nan for r in rows], dtype=float)


def _nan_stats(values) -> tuple[float, float, float]:
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    return (np.nan, np.nan, np.nan) if a.size == 0 else (a.mean(), a.min(), a.max())


def _groups(rows: Sequence[dict], names: Sequence[str]) -> dict[str, list[dict]]:
    """Rows grouped by their values of the factors `names` ("a=1, b=2" labels)."""
    out: dict[str, list[dict]] = {}
    for r in rows:
        out.setdefault(", ".join(f"{o}={_label(r['params'].get(o))}" for o in names), []).append(r)
    return out


def _plots(study: Study, rows: Sequence[dict], out: Path) -> list[Path]:
    from matplotlib.figure import Figure

    metrics = [m for m in study.metrics if np.isfinite(_metric_array(rows, m)).any()]
    if not rows or not metrics:
        return []
    ncol = min(3, len(metrics))
    nrow = math.ceil(len(metrics) / ncol)
    paths = []

    def figure():
        fig = Figure(figsize=(4.6 * ncol, 3.4 * nrow), dpi=110, layout="constrained")
        return fig, fig.subplots(nrow, ncol, squeeze=False).ravel()

    def finish(fig, axes, name):
        for ax in axes[len(metrics):]:
            ax.set_visible(False)
        paths.append(save_figure(fig, out / name))

    sampled = study.mode == "random"
    grid_factors = [f for f in study.factors if not f.is_random and not sampled]
    bad = np.array([r["status"] != "ok" for r in rows])  # diverged / error: metrics of a partial run
    for f in study.factors:
        xs = [r["params"].get(f.name) for r in rows]
        if len({canon(x) for x in xs}) < 2:
            continue
        fig, axes = figure()
        if f.is_random or sampled:  # scattered samples
            if all(is_real(x) for x in xs):
                pos, ticks = np.array(xs, dtype=float), None
            else:
                keys = sorted({canon(x) for x in xs})
                pos, ticks = np.array([keys.index(canon(x)) for x in xs], dtype=float), keys
            for ax, m in zip(axes, metrics, strict=False):
                ax.scatter(pos[~bad], _metric_array(rows, m)[~bad], s=14)
                if ticks:
                    ax.set_xticks(range(len(ticks)), [_label(json.loads(k)) for k in ticks])
        else:
            levels = [json.loads(canon(v)) for v in f.levels]
            keys = [canon(v) for v in levels]
            x = np.array(levels, dtype=float) if all(is_real(v) for v in levels) else np.arange(len(levels))
            pos = np.array([x[keys.index(canon(v))] for v in xs], dtype=float)
            groups = _groups(rows, [g.name for g in grid_factors if g is not f])
            ctl = [g.name for g in grid_factors if g is not f and g.path[:1] == ("controller",)]
            if len(groups) > 6 and ctl:  # one line per controller, band over the other factors
                groups = _groups(rows, ctl[:1])
            if len(groups) > 6:  # too many lines: one mean line with a min/max band
                groups = {"mean, min-max over the other factors": list(rows)}
            for ax, m in zip(axes, metrics, strict=False):
                for label, grp in groups.items():
                    vals = _metric_array(grp, m)
                    at = np.array([canon(r["params"].get(f.name)) for r in grp])
                    stats = np.array([_nan_stats(vals[at == k]) for k in keys])
                    (line,) = ax.plot(x, stats[:, 0], marker="o", label=label or None)
                    if np.any(stats[:, 2] > stats[:, 1]):
                        ax.fill_between(x, stats[:, 1], stats[:, 2], alpha=0.2, color=line.get_color())
                if not all(is_real(v) for v in levels):
                    ax.set_xticks(x, [_label(v) for v in levels])
        for ax, m in zip(axes, metrics, strict=False):
            if bad.any():
                ax.scatter(pos[bad], _metric_array(rows, m)[bad], marker="x", color="red", s=40, zorder=3,
                           label="diverged / error (partial run)")
            if ax is axes[0] and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize="x-small")
            ax.set(xlabel=f"{f.name} ({f.mode} of {f.param})", ylabel=METRIC_LABELS.get(m, m))
            ax.grid(alpha=0.3)
        fig.suptitle(f"{study.name}: metrics vs {f.name}")
        finish(fig, axes, f"metric_vs_{_safe(f.name)}.png")

    multi = [f for f in grid_factors if len(f.levels) > 1]
    for fa, fb in itertools.combinations(multi, 2):
        ka = [canon(v) for v in fa.levels]
        kb = [canon(v) for v in fb.levels]
        fig, axes = figure()
        for ax, m in zip(axes, metrics, strict=False):
            cells: dict[tuple[int, int], list[float]] = {}
            flagged = set()
            for r, v, b_ in zip(rows, _metric_array(rows, m), bad, strict=True):
                a, b = canon(r["params"].get(fa.name)), canon(r["params"].get(fb.name))
                if a in ka and b in kb:
                    cells.setdefault((ka.index(a), kb.index(b)), []).append(v)
                    if b_:
                        flagged.add((ka.index(a), kb.index(b)))
            grid = np.full((len(kb), len(ka)), np.nan)
            for (i, j), vals in cells.items():
                grid[j, i] = _nan_stats(vals)[0]
            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis")
            fig.colorbar(im, ax=ax)
            for (j, i), v in np.ndenumerate(grid):
                text = ("-" if np.isnan(v) else f"{v:.3g}") + ("*" if (i, j) in flagged else "")
                ax.text(i, j, text, ha="center", va="center", fontsize=7, color="w")
            ax.set_xticks(range(len(ka)), [_label(v) for v in fa.levels])
            ax.set_yticks(range(len(kb)), [_label(v) for v in fb.levels])
            ax.set(xlabel=fa.name, ylabel=fb.name, title=METRIC_LABELS.get(m, m))
        more = " (mean over the other factors)" if len(study.factors) > 2 else ""
        star = "; * = some cases diverged or failed (partial runs)" if bad.any() else ""
        fig.suptitle(f"{study.name}: {fb.name} vs {fa.name}{more}{star}")
        finish(fig, axes, f"heatmap_{_safe(fa.name)}__{_safe(fb.name)}.png")
    return paths


