"""Thinning a long series for a chart keeps every extreme: the largest and smallest value of each
bucket survive, in the order they came, and a short series is left as it is."""

from __future__ import annotations

import numpy as np

from twin.report.thin import BUCKETS, min_max


def test_a_ten_minute_run_keeps_every_spike_and_dip():
    n = 600 * 240  # 10 minutes at 240 Hz
    t = np.arange(n) / 240.0
    rng = np.random.default_rng(7)
    y = np.column_stack([np.sin(t), rng.normal(0, 1e-3, n)])
    y[77_777, 0], y[100_001, 1] = 5.0, -3.0  # one sample each, far from its neighbours
    x, kept = min_max(t, y)
    assert len(x) == len(kept) <= 2 * BUCKETS
    assert kept[:, 0].max() == 5.0 and kept[:, 1].min() == -3.0
    # each column's extremes overall and per bucket survive exactly
    assert kept[:, 0].min() == y[:, 0].min() and kept[:, 1].max() == y[:, 1].max()
    spike = int(np.flatnonzero(kept[:, 0] == 5.0)[0])
    assert abs(x[spike] - t[77_777]) <= n / BUCKETS / 240.0  # within one bucket of where it was
    assert np.all(np.diff(x) >= 0)


def test_the_extreme_that_came_first_is_drawn_first():
    t = np.arange(1000.0)
    y = np.zeros(1000)
    y[10], y[20] = 1.0, -1.0  # both in the first bucket (500 samples): the maximum came first
    x, kept = min_max(t, y, buckets=2)
    assert kept[:2, 0].tolist() == [1.0, -1.0]
    assert x.tolist() == [0.0, 499.0, 500.0, 999.0]


def test_a_short_series_is_kept_whole():
    t = np.arange(50.0)
    y = np.arange(50.0) ** 2
    x, kept = min_max(t, y)
    assert np.array_equal(x, t) and np.array_equal(kept[:, 0], y)


def test_a_missing_value_hides_no_extreme():
    t = np.arange(2000.0)
    y = np.zeros(2000)
    y[5], y[6] = np.nan, 2.0
    _, kept = min_max(t, y, buckets=10)
    assert kept[:, 0].max() == 2.0
