"""Figure layout without matplotlib's tight-bbox pass (which cost ~40 % of a run's figure time): the
margins and gaps of a grid of axes (with colorbars and legends outside) from a few text measurements,
the tick labels formatted from each axis' locator and formatter.  Three passes: the ticks depend on the
axes' size, which depends on the margins.
"""

from __future__ import annotations

import numpy as np
from matplotlib import cbook, rcParams
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties

PAD = 4.0 / 72  # inches: space between a text and the figure edge or a neighbouring axes' decorations
_SLACK = 1.0 / 72  # inches added to every measured extent (hinting, rounding at the save DPI)


class _Measure:
    """Text sizes in inches from a 1x1-pixel Agg renderer at the figure's DPI (renderer and sizes cached
    per DPI across figures: the same tick labels recur)."""

    _renderers: dict[float, RendererAgg] = {}
    _sizes: dict[tuple, tuple[float, float]] = {}

    def __init__(self, fig: Figure):
        self.fig = fig
        self.dpi = float(fig.dpi)
        if self.dpi not in self._renderers:
            self._renderers[self.dpi] = RendererAgg(1, 1, self.dpi)
        self.renderer = self._renderers[self.dpi]

    def text(self, s: str, size) -> tuple[float, float]:
        """(width, height) in inches of one line of text `s` at font size `size` (points or name)."""
        if not s:
            return 0.0, 0.0
        key = (s, size, self.dpi, rcParams["font.family"][0] if rcParams["font.family"] else "")
        if key not in self._sizes:
            if len(self._sizes) > 4096:
                self._sizes.clear()
            prop = FontProperties(size=size)
            w, h, _ = self.renderer.get_text_width_height_descent(s, prop, ismath=cbook.is_math_text(s))
            self._sizes[key] = (w / self.dpi + _SLACK, h / self.dpi + _SLACK)
        return self._sizes[key]

    def extent(self, artist) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) in inches of an artist's window extent."""
        bb = artist.get_window_extent(self.renderer)
        return bb.x0 / self.dpi, bb.y0 / self.dpi, bb.x1 / self.dpi, bb.y1 / self.dpi


# per axis, the two sides across it: (index in [left, bottom, right, top], tick-label switch of
# Axis.set_tick_params, its rc default, the matching Axis.get_label_position)
_SIDES = {"x": ((1, "label1On", "xtick.labelbottom", "bottom"), (3, "label2On", "xtick.labeltop", "top")),
          "y": ((0, "label1On", "ytick.labelleft", "left"), (2, "label2On", "ytick.labelright", "right"))}

_MARKS = {"x": (("tick1On", "xtick.bottom"), ("tick2On", "xtick.top")),
          "y": (("tick1On", "ytick.left"), ("tick2On", "ytick.right"))}


def _tick_kw(axis, key: str, rc_key: str):
    return getattr(axis, "_major_tick_kw", {}).get(key, rcParams[rc_key])


def _tick_labels(axis) -> tuple[np.ndarray, list[str], str]:
    """(positions in [0, 1] along the axis, labels, offset text) of the major ticks in view, as
    `Axis._update_ticks` formats them."""
    lo, hi = sorted(axis.get_view_interval())
    locs = np.asarray(axis.get_major_locator()(), dtype=float)
    labels = axis.get_major_formatter().format_ticks(locs)
    offset = axis.get_major_formatter().get_offset()
    span = hi - lo
    tol = 1e-10 * max(abs(lo), abs(hi), span)
    keep = (locs >= lo - tol) & (locs <= hi + tol)
    frac = (locs[keep] - lo) / span if span > 0 else np.full(keep.sum(), 0.5)
    return frac, [lab for lab, k in zip(labels, keep, strict=True) if k], offset


def _decorations(ax, m: _Measure) -> np.ndarray:
    """How far (inches) the axes' texts reach beyond its box: [left, bottom, right, top]."""
    x0, y0, x1, y1 = np.asarray(ax.get_position(original=True).extents) * np.tile(m.fig.get_size_inches(), 2)
    w, h = x1 - x0, y1 - y0
    out = np.zeros(4)
    if ax.get_aspect() != "auto" or ax.get_box_aspect() is not None:
        ax.apply_aspect()  # the view limits (adjustable="datalim") or the box, as drawn
    y_offset = ""
    for name, axis, length in (("x", ax.xaxis, w), ("y", ax.yaxis, h)):
        if not axis.get_visible():
            continue
        lo_side, hi_side = _SIDES[name]
        tick_sides = [s[0] for s in (lo_side, hi_side) if _tick_kw(axis, s[1], s[2])]
        fontsize = _tick_kw(axis, "labelsize", f"{name}tick.labelsize")
        frac, labels, offset = _tick_labels(axis) if tick_sides else (np.zeros(0), [], "")
        sizes = np.array([m.text(s, fontsize) for s in labels]).reshape(-1, 2)
        along, across = (sizes[:, 0], sizes[:, 1]) if name == "x" else (sizes[:, 1], sizes[:, 0])
        if len(labels):  # centred on their tick: the end ones may reach past the axes' ends
            lo_end, hi_end = (0, 2) if name == "x" else (1, 3)
            out[lo_end] = max(out[lo_end], float(np.max(along / 2 - frac * length)))
            out[hi_end] = max(out[hi_end], float(np.max(frac * length + along / 2 - length)))
        reach = (_tick_kw(axis, "size", f"{name}tick.major.size")
                 + _tick_kw(axis, "pad", f"{name}tick.major.pad")) / 72  # tick length + pad (points)
        label_pos = axis.get_label_position()
        label = axis.label.get_text()
        _, oh = m.text(offset, fontsize)
        tick_len = _tick_kw(axis, "size", f"{name}tick.major.size") / 72
        for (side, *_, pos), mark in zip((lo_side, hi_side), _MARKS[name], strict=True):
            need = tick_len if _tick_kw(axis, *mark) else 0.0  # tick marks without labels
            if side in tick_sides and len(labels):
                need = reach + float(across.max())
            if offset and name == "x" and side in tick_sides:  # below the tick labels, at the right end
                need = max(need, reach + float(across.max(initial=0.0)) + axis.OFFSETTEXTPAD / 72 + oh)
            if label and label_pos == pos:  # beyond the tick labels (a y label is rotated: its height)
                lw, lh = m.text(label, axis.label.get_fontsize())
                need += axis.labelpad / 72 + lh
                over = max(0.0, (lw - length) / 2)  # a label longer than the axes is centred on it
                for end in ((0, 2) if name == "x" else (1, 3)):
                    out[end] = max(out[end], over)
            out[side] = max(out[side], need)
        if offset and name == "y":  # above the axes, at its left end
            out[3] = max(out[3], axis.OFFSETTEXTPAD / 72 + oh)
            y_offset = offset
    for title in (ax.title, ax._left_title, ax._right_title):
        if title.get_text():
            tx0, ty0, tx1, ty1 = m.extent(title)  # at its position before drawing: axes top + titlepad
            need = ty1 - y1 + _SLACK
            if y_offset:  # drawing moves a title above an offset text it meets (at the axes' left end)
                ow, oh = m.text(y_offset, ax.yaxis.offsetText.get_fontsize())
                if tx0 < x0 + ow:
                    need = max(need, ax.yaxis.OFFSETTEXTPAD / 72 + oh + (ty1 - ty0) + _SLACK)
            out[3] = max(out[3], need)
            out[0] = max(out[0], x0 - tx0 + _SLACK)
            out[2] = max(out[2], tx1 - x1 + _SLACK)
    legend = ax.get_legend()
    if legend is not None and getattr(legend, "_loc", 0) != 0:  # "best" stays inside the axes
        lx0, ly0, lx1, ly1 = m.extent(legend)
        out = np.maximum(out, [x0 - lx0 + _SLACK, y0 - ly0 + _SLACK, lx1 - x1 + _SLACK, ly1 - y1 + _SLACK])
    return out


def _cell(ax):
    ss = ax.get_subplotspec()
    return None if ss is None else ss.get_topmost_subplotspec()


def fix_layout(fig: Figure, passes: int = 3) -> None:
    """Place the axes of `fig` (one top-level GridSpec, no layout engine) so that every text fits
    (`subplots_adjust`); call after drawing, before saving."""
    m = _Measure(fig)
    W, H = fig.get_size_inches()
    axes = [ax for ax in fig.axes if ax.get_visible() and _cell(ax) is not None]
    if not axes:
        return
    gs = _cell(axes[0]).get_gridspec()
    nrows, ncols = gs.get_geometry()
    for _ in range(passes):
        left, right = np.zeros(ncols), np.zeros(ncols)
        bottom, top = np.zeros(nrows), np.zeros(nrows)
        for ax in axes:
            cell = _cell(ax)
            if cell.get_gridspec() is not gs:
                raise ValueError("fix_layout: the axes are not on one GridSpec")
            deco = _decorations(ax, m)
            c0, c1 = cell.colspan.start, cell.colspan.stop - 1
            r0, r1 = cell.rowspan.start, cell.rowspan.stop - 1
            # the axes' box inside its cell (a colorbar shares the cell with its parent)
            bx = np.asarray(ax.get_position(original=True).extents) * [W, H, W, H]
            cx = np.asarray(cell.get_position(fig).extents) * [W, H, W, H]
            inset = [bx[0] - cx[0], bx[1] - cx[1], cx[2] - bx[2], cx[3] - bx[3]]
            left[c0] = max(left[c0], deco[0] - inset[0])
            bottom[r1] = max(bottom[r1], deco[1] - inset[1])
            right[c1] = max(right[c1], deco[2] - inset[2])
            top[r0] = max(top[r0], deco[3] - inset[3])
        sup = fig._suptitle
        sup_h = 0.0
        if sup is not None and sup.get_visible() and sup.get_text():
            sup_h = (1.0 - sup.get_position()[1]) * H + m.text(sup.get_text(), sup.get_fontsize())[1]
        l_in = max(left[0], 0.0) + PAD
        r_in = max(right[-1], 0.0) + PAD
        b_in = max(bottom[-1], 0.0) + PAD
        t_in = max(top[0], 0.0) + (sup_h + 1.0 / 72 if sup_h else PAD)  # the suptitle: from its y down
        wgap = max([right[c] + left[c + 1] + 2 * PAD for c in range(ncols - 1)], default=0.0)
        hgap = max([bottom[r] + top[r + 1] + 2 * PAD for r in range(nrows - 1)], default=0.0)
        aw = (W - l_in - r_in - (ncols - 1) * wgap) / ncols
        ah = (H - b_in - t_in - (nrows - 1) * hgap) / nrows
        if aw <= 0.1 * W / ncols or ah <= 0.1 * H / nrows:  # texts too big for the figure: keep a plot
            aw, ah = max(aw, 0.1 * W / ncols), max(ah, 0.1 * H / nrows)
        params = dict(left=l_in / W, right=1 - r_in / W, bottom=b_in / H, top=1 - t_in / H,
                      wspace=wgap / aw, hspace=hgap / ah)
        if all(abs(getattr(fig.subplotpars, k) - v) < 1e-9 for k, v in params.items()):
            break  # converged: the same ticks as in the previous pass
        fig.subplots_adjust(**params)

