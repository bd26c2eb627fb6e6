"""The power of the paired verdict (twin.sweep.power) against values computed another way: the
verdict itself (paired.pair and paired.problems) over every outcome of a few scenarios, weighted by
exact multinomial probabilities; McNemar's exact test (stats.mcnemar_exact) for the critical
counts; a normal approximation at 100k scenarios; random draws."""

from __future__ import annotations

import functools
import math

import numpy as np
import pyarrow as pa
import pytest

from twin.sweep import paired, power
from twin.sweep.stats import mcnemar_exact


def _side(label: str, ok: list[bool]) -> paired.Side:
    n = len(ok)
    table = pa.table({
        "scenario": pa.array(range(n), pa.int64()),
        "box.x_m": pa.array([0.2] * n),
        "outcome": ["ok" if o else "error" for o in ok],
        "error": ["" if o else "cycle 1: suction on at (0.2, 0.7), nothing sensed" for o in ok],
        "placement_error_mm": pa.array([None] * n, pa.float64()),
    })
    return paired.side_from_table(table, label)


def _flipped(n: int, worse: int, better: int) -> paired.Paired:
    """n scenarios: `worse` go ok -> failed, `better` failed -> ok, the rest ok in both."""
    before = [i >= worse + better or i < worse for i in range(n)]
    after = [i >= worse for i in range(n)]
    return paired.pair(_side("reference", before), _side("new", after))


@functools.cache
def _fails(n: int, worse: int, better: int) -> bool:
    return bool(paired.problems(_flipped(n, worse, better), "significant", 0.5))


def verdict_power(n: int, discordance: float, drop: float) -> float:
    """P(the significant rule fails) by enumeration: every (worse, better) split of n scenarios,
    judged by paired.problems itself, weighted by its multinomial probability."""
    share = max(discordance, drop)
    p_worse, p_better = (share + drop) / 2, (share - drop) / 2
    total = 0.0
    for worse in range(n + 1):
        for better in range(n - worse + 1):
            if _fails(n, worse, better):
                total += (math.comb(n, worse) * math.comb(n - worse, better) * p_worse**worse
                          * p_better**better * (1 - share) ** (n - worse - better))
    return total


@pytest.mark.parametrize(("n", "discordance", "drop"), [
    (6, 0.0, 0.3), (10, 0.2, 0.1), (10, 0.5, 0.45), (14, 0.3, 0.0), (14, 0.0, 0.5),
    (16, 1.0, 0.6), (18, 0.25, 0.25), (18, 0.05, 0.2), (5, 0.5, 0.5)])
def test_the_power_is_the_verdicts_own_over_every_outcome(n, discordance, drop):
    assert power.drop_power(n, discordance, drop) == pytest.approx(
        verdict_power(n, discordance, drop), abs=1e-12)


def test_the_detectable_drop_is_the_smallest_with_80_percent_power():
    for n, discordant in ((12, 0), (14, 6), (16, 8)):
        pct = power.detectable_drop_pct(n, discordant)
        share = discordant / n
        assert verdict_power(n, share, pct / 100) >= 0.8
        assert verdict_power(n, share, pct / 100 - 1e-6) < 0.8
    assert power.detectable_drop_pct(5, 0) is None  # 5 one-way flips: p = 0.0625, never < 0.05


def test_the_critical_counts_are_mcnemars():
    # m(d): the most failed->ok of d flips with which the rest, ok->failed, is significant; both
    # branches of stats.half_binomial_cdf (exact integers up to 2000 flips, logs beyond)
    for start, stop, step in ((0, 200, 1), (190, 2600, 37)):
        m = power.critical_better(start, stop)
        for d in range(start, stop + 1, step):
            k = int(m[d - start])
            assert k == -1 or (mcnemar_exact(d - k, k) < 0.05 and d - k > k), d
            assert not (mcnemar_exact(d - k - 1, k + 1) < 0.05 and d - k - 1 > k + 1), d
    assert list(power.critical_better(0, 12)) == [-1] * 6 + [0, 0, 0, 1, 1, 1, 2]
    assert power.MIN_FLIPS == 6 and mcnemar_exact(6, 0) < 0.05 <= mcnemar_exact(5, 0)


def test_100k_scenarios_agree_with_the_normal_approximation_and_stay_fast():
    # 1 % of 100k flipped either way: (z 0.975 + z 0.8) sqrt(psi / n), about 0.0886 points
    pct = power.detectable_drop_pct(100_000, 1_000)
    normal = 100 * (1.959964 + 0.841621) * math.sqrt(0.01 / 100_000)
    assert pct == pytest.approx(normal, rel=0.03)
    assert power.drop_power(100_000, 0.01, pct / 100) == pytest.approx(0.8, abs=1e-6)


def test_random_draws_fail_the_verdict_as_often_as_the_power_says():
    n, discordant = 300, 24
    pct = power.detectable_drop_pct(n, discordant)
    share, drop = discordant / n, pct / 100
    rng = np.random.default_rng(7)
    draws = rng.multinomial(n, [(share + drop) / 2, (share - drop) / 2, 1 - share], size=4000)
    failed = [w > b and mcnemar_exact(int(w), int(b)) < 0.05 for w, b, _ in draws]
    assert np.mean(failed) == pytest.approx(0.8, abs=3 * math.sqrt(0.8 * 0.2 / 4000))
