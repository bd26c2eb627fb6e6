"""The statistics of a sweep: the success rate with its Wilson score interval, placement-error
percentiles and the failures grouped by reason. Nothing here depends on wall-clock time, so a
summary is the same for the same scenarios (a statistical golden compares it)."""

from __future__ import annotations

import math
import re

import numpy as np

Z95 = 1.959963984540054  # the standard normal's 97.5th percentile
_CYCLE = re.compile(r"^cycle \d+: ")
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e-?\d+)?")


def wilson(ok: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate ok/n: unlike the normal approximation it stays
    within [0, 1] and is sensible at 0 or n successes. n = 0: [0, 1]."""
    if n == 0:
        return 0.0, 1.0
    p = ok / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if ok == 0 else max(0.0, centre - half)  # exact ends where rounding would miss them
    hi = 1.0 if ok == n else min(1.0, centre + half)
    return lo, hi


def reason(error: str) -> str:
    """A failure's reason: its error line without the cycle number and with every number as #, so
    "cycle 3: placed 2.31 mm from (0.2, 0.7), beyond 2 mm" and its kin count as one reason."""
    return _NUMBER.sub("#", _CYCLE.sub("", error)) or "error"


def percentiles(values: list[float]) -> dict:
    """p50, p95 and max of values (numpy's linear interpolation); None each when there are none."""
    if not values:
        return {"count": 0, "p50": None, "p95": None, "max": None}
    arr = np.asarray(values, dtype=float)
    return {
        "count": len(values),
        "p50": float(np.percentile(arr, 50)),
        "p95": float(np.percentile(arr, 95)),
        "max": float(arr.max()),
    }


def summarize(rows: list[dict]) -> dict:
    """The summary of rows: scenarios, ok, failed, success_rate, wilson95, placement error
    percentiles (over the scenarios that placed the box at least once) and failures by reason
    (most frequent first)."""
    n = len(rows)
    ok = sum(r["outcome"] == "ok" for r in rows)
    lo, hi = wilson(ok, n)
    errors = [r["placement_error_mm"] for r in rows if r["placement_error_mm"] is not None]
    counts: dict[str, int] = {}
    for r in rows:
        if r["outcome"] != "ok":
            key = reason(r["error"])
            counts[key] = counts.get(key, 0) + 1
    return {
        "scenarios": n,
        "ok": ok,
        "failed": n - ok,
        "success_rate": ok / n if n else 0.0,
        "wilson95": [lo, hi],
        "placement_error_mm": percentiles(errors),
        "failures_by_reason": dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))),
    }


# Paired and unpaired comparisons of two sweeps. "Difference" is always new minus reference.

EXACT_UP_TO = 2000  # binomial tails summed in exact integers up to this many trials, in logs beyond


def newcombe_unpaired(ok1: int, n1: int, ok2: int, n2: int, z: float = Z95) -> tuple[float, float]:
    """Newcombe's hybrid score interval (1998, method 10 for independent proportions) of
    ok1/n1 - ok2/n2: each rate's Wilson interval, the distances to its ends added in squares."""
    p1, p2 = ok1 / n1 if n1 else 0.0, ok2 / n2 if n2 else 0.0
    l1, u1 = wilson(ok1, n1, z)
    l2, u2 = wilson(ok2, n2, z)
    d = p1 - p2
    return d - math.hypot(p1 - l1, u2 - p2), d + math.hypot(u1 - p1, p2 - l2)


def newcombe_paired(
    both: int, only1: int, only2: int, neither: int, z: float = Z95
) -> tuple[float, float]:
    """Newcombe's interval (1998, method 10 for paired proportions) of p1 - p2, where p1 =
    (both + only1) / n and p2 = (both + only2) / n: the two marginal Wilson intervals combined
    with phi, the correlation of the pairs, corrected towards 0 by n/2 when positive (as
    Newcombe defines it; 0 when a margin is empty)."""
    n = both + only1 + only2 + neither
    if n == 0:
        return -1.0, 1.0
    s1, s2 = both + only1, both + only2
    p1, p2 = s1 / n, s2 / n
    l1, u1 = wilson(s1, n, z)
    l2, u2 = wilson(s2, n, z)
    margins = s1 * (n - s1) * s2 * (n - s2)
    cross = both * neither - only1 * only2
    if margins == 0:
        phi = 0.0
    elif cross > n / 2:
        phi = (cross - n / 2) / math.sqrt(margins)
    elif cross >= 0:
        phi = 0.0
    else:
        phi = cross / math.sqrt(margins)
    d = p1 - p2
    dl = (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2
    du = (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2
    return max(-1.0, d - math.sqrt(max(dl, 0.0))), min(1.0, d + math.sqrt(max(du, 0.0)))


def half_binomial_cdf(k: int, n: int) -> float:
    """P(X <= k) for X ~ Binomial(n, 1/2): exact (integers) up to EXACT_UP_TO trials, else a
    log-space sum (relative error about 1e-12)."""
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    if n <= EXACT_UP_TO:
        return sum(math.comb(n, i) for i in range(k + 1)) / 2**n
    logs = _log_half_pmf(n)[: k + 1]
    top = logs.max()
    return float(min(1.0, math.exp(top) * np.exp(logs - top).sum()))


def _log_half_pmf(n: int) -> np.ndarray:
    """log P(X = i), i = 0..n, X ~ Binomial(n, 1/2), by the recurrence
    C(n, i) = C(n, i-1) (n-i+1) / i."""
    i = np.arange(1, n + 1, dtype=float)
    return np.concatenate(([0.0], np.cumsum(np.log(n - i + 1) - np.log(i)))) - n * math.log(2)


def mcnemar_exact(worse: int, better: int) -> float:
    """McNemar's exact test: the two-sided p-value of worse vs better discordant pairs under
    H0 (each discordant pair equally likely either way), 2 P(X <= min) capped at 1."""
    n = worse + better
    return 1.0 if n == 0 else min(1.0, 2 * half_binomial_cdf(min(worse, better), n))


def median_ci(values: np.ndarray, level: float = 0.95) -> tuple[float, float, float] | None:
    """The median of values and its distribution-free interval from order statistics (the sign
    test's inversion): [x(k), x(n+1-k)] for the largest k with 2 P(Bin(n, 1/2) <= k-1) <= 1 -
    level, so its coverage is at least level. Too few values for that (n < 6 at 95 %): the
    interval is the range. None when there are no values."""
    x = np.sort(np.asarray(values, dtype=float))
    n = len(x)
    if n == 0:
        return None
    median = float(np.median(x))
    lo, hi = 0, n + 1  # k = 0 stands for "no order statistic qualifies"
    while hi - lo > 1:  # the tail P(X <= k-1) grows with k: bisect for the largest qualifying k
        mid = (lo + hi) // 2
        if 2 * half_binomial_cdf(mid - 1, n) <= 1 - level:
            lo = mid
        else:
            hi = mid
    if lo == 0:
        return median, float(x[0]), float(x[-1])
    return median, float(x[lo - 1]), float(x[n - lo])
