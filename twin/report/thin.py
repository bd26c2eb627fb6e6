"""Thinning a long run for a plot without losing what matters in it: the run is cut into buckets
of equal length and each bucket keeps, for every series, its smallest and its largest value, in
the order they came (a min/max decimation, as oscilloscopes draw). Every peak, dip and step a
reader could see in the full series is still drawn, at most one bucket (1/BUCKETS of the plot's
width) from where it was."""

from __future__ import annotations

import numpy as np

BUCKETS = 200  # per plot: one min and one max per two pixel columns of a 800 px wide chart


def min_max(t: np.ndarray, y: np.ndarray, buckets: int = BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """(t', y') with t (n,) and y (n, m): each bucket of samples becomes two, at its first and
    last time, holding each column's extremes (the one that came first, first). As they are when
    there are no more than 2 * buckets samples."""
    n = len(t)
    y = np.asarray(y, dtype=np.float64).reshape(n, -1)
    if n <= 2 * buckets:
        return np.asarray(t, dtype=np.float64), y
    size = -(-n // buckets)  # ceil: every sample falls in one bucket
    count = -(-n // size)  # buckets actually used
    padded = np.concatenate([y, np.repeat(y[-1:], size * count - n, axis=0)])
    shaped = padded.reshape(count, size, y.shape[1])
    nan = np.isnan(shaped)  # a missing value hides no extreme
    low_i = np.where(nan, np.inf, shaped).argmin(axis=1)
    high_i = np.where(nan, -np.inf, shaped).argmax(axis=1)
    low = np.take_along_axis(shaped, low_i[:, None, :], axis=1)[:, 0]
    high = np.take_along_axis(shaped, high_i[:, None, :], axis=1)[:, 0]
    low_first = low_i <= high_i
    out = np.empty((2 * count, y.shape[1]))
    out[0::2] = np.where(low_first, low, high)
    out[1::2] = np.where(low_first, high, low)
    starts = np.arange(count) * size
    ends = np.minimum(starts + size - 1, n - 1)
    times = np.empty(2 * count)
    times[0::2], times[1::2] = t[starts], t[ends]
    return times, out
