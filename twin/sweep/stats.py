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
    return {"count": len(values), "p50": float(np.percentile(arr, 50)), "p95": float(np.percentile(arr, 95)),
            "max": float(arr.max())}


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
    return {"scenarios": n, "ok": ok, "failed": n - ok, "success_rate": ok / n if n else 0.0, "wilson95": [lo, hi],
            "placement_error_mm": percentiles(errors),
            "failures_by_reason": dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))}
