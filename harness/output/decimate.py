"""Display-resolution decimation of time series (numpy only): per column of equal time width, the first,
minimum, maximum and last sample, plus every non-finite one (a NaN breaks a line): what the eye sees of
a column, and every extremum of the series.
"""

from __future__ import annotations

import numpy as np


def envelope_indices(t: np.ndarray, y: np.ndarray, n_columns: int) -> np.ndarray:
    """Sorted indices (m,) of the samples of (t (n,) non-decreasing, y (n,)) kept at n_columns >= 1
    equal time bins; m <= 4 n_columns + the non-finite y; all of range(n) when n <= 4 n_columns."""
    t = np.asarray(t, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    n, n_columns = t.shape[0], int(n_columns)
    if y.shape[0] != n:
        raise ValueError(f"t has {n} samples, y has {y.shape[0]}")
    if n_columns < 1:
        raise ValueError(f"n_columns = {n_columns}: must be >= 1")
    if n <= 4 * n_columns:
        return np.arange(n)
    span = t[-1] - t[0]
    if not np.isfinite(span) or span <= 0:
        col = np.zeros(n, dtype=np.int64)
    else:
        # (t - t0) / span first: in [0, 1], no overflow even for a subnormal span
        col = np.minimum(((t - t[0]) / span * n_columns).astype(np.int64), n_columns - 1)
    if np.any(np.diff(col) < 0):
        raise ValueError("t must be non-decreasing")
    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])  # first sample of each non-empty column
    ends = np.r_[starts[1:], n] - 1  # last sample of each column
    finite = np.isfinite(y)
    # per column: the earliest sample holding its min / its max (non-finite values never win; a
    # column without a finite value gives its first sample), from reduceat, no sort
    lo_key = np.where(finite, y, np.inf)
    hi_key = np.where(finite, y, -np.inf)
    counts = ends - starts + 1
    first_lo = _first_per_column(lo_key == np.repeat(np.minimum.reduceat(lo_key, starts), counts), col)
    first_hi = _first_per_column(hi_key == np.repeat(np.maximum.reduceat(hi_key, starts), counts), col)
    keep = ~finite
    for idx in (starts, ends, first_lo, first_hi):
        keep[idx] = True
    return np.flatnonzero(keep)


def _first_per_column(mask: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Index of the first True of `mask` in each column (every column has one)."""
    idx = np.flatnonzero(mask)
    c = col[idx]
    return idx[np.r_[True, c[1:] != c[:-1]]]


def envelope(t: np.ndarray, y: np.ndarray, n_columns: int) -> tuple[np.ndarray, np.ndarray]:
    """(t_kept (m,), y_kept (m,)): the samples of `envelope_indices`, in time order."""
    idx = envelope_indices(t, y, n_columns)
    return np.asarray(t).reshape(-1)[idx], np.asarray(y).reshape(-1)[idx]

