"""Decimation of what a figure draws (never of what is computed): a min/max envelope per pixel.

A line of 120 000 samples drawn into an axes about 1000 pixels wide puts ~120 samples in each
pixel column; drawing them all costs time and shows nothing more than each column's extremes.
:func:`envelope_indices` keeps, for each column (a bin of equal *time* width), the bin's first,
lowest, highest and last sample, in time order, so that spikes, steps and stick-slip plateaus
look the same as with every sample drawn. A striding decimation (every k-th sample) would drop
a one-sample spike; this keeps it. NaN samples stay gaps (one NaN of each bin that holds any is
kept). The indices select real samples: the drawn points are a subset of the log's.

A scatter (residual against speed) shows a distribution, which an envelope would misdraw as
two bands of extremes: :func:`scatter_indices` draws a uniform sample plus every outlier
beyond the sample's range.
"""

from __future__ import annotations

import numpy as np

#: a line is decimated only when it has more than this many points per pixel column
POINTS_PER_COLUMN = 4


def envelope_indices(t: np.ndarray, y: np.ndarray, columns: int) -> np.ndarray:
    """Indices of the samples to draw of ``y`` against ``t`` in ``columns`` pixel columns.

    ``t`` is the x coordinate (s, increasing); ``y`` the values (any unit, NaN allowed).
    Returns every index when ``len(y) <= POINTS_PER_COLUMN * columns``; otherwise, per bin of
    equal width in ``t`` (``columns`` bins), the first, the lowest, the highest and the last
    sample and the first NaN if there is one, sorted by index (time order). The min and max
    of ``y`` over the kept samples of any bin equal those over all of its samples.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    n = len(y)
    columns = max(int(columns), 1)
    if n <= POINTS_PER_COLUMN * columns or n < 2:
        return np.arange(n)
    bins = pixel_bins(t, columns)
    starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    ends = np.r_[starts[1:], n] - 1
    nan = np.isnan(y)
    lo = np.where(nan, np.inf, y)
    hi = np.where(nan, -np.inf, y)
    keep = [starts, ends,
            _first_where(lo == np.repeat(np.minimum.reduceat(lo, starts), ends - starts + 1),
                         bins),
            _first_where(hi == np.repeat(np.maximum.reduceat(hi, starts), ends - starts + 1),
                         bins)]
    if nan.any():
        keep.append(_first_where(nan, bins))
    mask = np.zeros(n, bool)
    for k in keep:
        mask[k] = True
    return np.flatnonzero(mask)


def pixel_bins(t: np.ndarray, columns: int) -> np.ndarray:
    """Bin number (0 .. columns-1) of each sample: equal widths in ``t`` between its ends.

    Non-finite times (which a log does not have) go to the nearest end bin.
    """
    t = np.asarray(t, float)
    finite = t[np.isfinite(t)]
    if len(finite) == 0 or finite[-1] <= finite[0]:
        return np.minimum(np.arange(len(t)) * columns // max(len(t), 1), columns - 1)
    pos = (t - finite[0]) / (finite[-1] - finite[0]) * columns
    pos = np.nan_to_num(pos, nan=0.0, posinf=columns - 1, neginf=0.0)
    b = np.clip(pos.astype(np.int64), 0, columns - 1)
    return np.maximum.accumulate(b)  # time order: a bin never goes back


def _first_where(mask: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """Per bin, the first index where ``mask`` holds (bins without one give nothing)."""
    idx = np.flatnonzero(mask)
    b = bins[idx]  # sorted, as bins and idx are
    return idx[np.r_[True, b[1:] != b[:-1]]] if len(idx) else idx


#: most points a scatter draws from its uniform sample (a cloud's density needs no more)
SCATTER_POINTS = 4000


def scatter_indices(y: np.ndarray, limit: int = SCATTER_POINTS) -> np.ndarray:
    """Indices of the points of a scatter of ``y`` (against anything) to draw.

    A scatter shows a distribution, so an envelope (which keeps only extremes) would paint
    false bands; instead every k-th sample (at most about ``limit``) keeps the density, and
    every sample above or below that sample's range is added so that outliers and spikes
    still show. All indices when ``len(y) <= 2 * limit``; NaN samples draw nothing.
    """
    y = np.asarray(y, float)
    n = len(y)
    if n <= 2 * limit:
        return np.arange(n)
    mask = np.zeros(n, bool)
    mask[::max(1, n // limit)] = True
    sample = y[mask]
    sample = sample[~np.isnan(sample)]
    if len(sample):
        mask |= (y > sample.max()) | (y < sample.min())
    return np.flatnonzero(mask)
