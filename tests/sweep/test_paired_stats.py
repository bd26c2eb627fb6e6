"""The paired statistics against values computed independently: published worked examples of
Newcombe's intervals, and exact binomial arithmetic (fractions) for McNemar's test and the
sign-test interval of a median."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pyarrow as pa
import pytest

from twin.sweep import paired
from twin.sweep.stats import (
    EXACT_UP_TO,
    half_binomial_cdf,
    mcnemar_exact,
    median_ci,
    newcombe_paired,
    newcombe_unpaired,
)


def test_newcombe_unpaired_matches_published_examples():
    # Newcombe (1998), Stat Med 17:873, Table II, example (a): 56/70 - 48/80, method 10
    lo, hi = newcombe_unpaired(56, 70, 48, 80)
    assert (round(lo, 4), round(hi, 4)) == (0.0524, 0.3339)
    # Fagerland, Lydersen & Laake (2017), ch. 4: Perondi et al. 2004, 7/34 - 1/34,
    # Newcombe hybrid score
    lo, hi = newcombe_unpaired(7, 34, 1, 34)
    assert (round(lo, 4), round(hi, 4)) == (0.0189, 0.3404)


def test_newcombe_paired_matches_a_published_example():
    # Fagerland, Lydersen & Laake (2017), ch. 8: Cavo et al. 2012, table [[59, 6], [16, 80]],
    # Newcombe square-and-add: estimate -0.0621, 95 % CI -0.1186 to -0.0046
    lo, hi = newcombe_paired(59, 6, 16, 80)
    assert (round(lo, 4), round(hi, 4)) == (-0.1186, -0.0046)
    assert lo < (6 - 16) / 161 < hi


def test_newcombe_paired_edges():
    assert newcombe_paired(0, 0, 0, 0) == (-1.0, 1.0)
    lo, hi = newcombe_paired(30, 0, 0, 0)  # all ok in both: an empty margin, phi 0
    assert lo < 0 < hi and -1 <= lo and hi <= 1
    lo, hi = newcombe_paired(0, 30, 0, 0)  # every pair better
    assert 0 < lo < hi == 1.0


def exact_two_sided(worse: int, better: int) -> Fraction:
    """McNemar's exact p by hand: 2 * sum_{i <= min} C(n, i) / 2^n, capped at 1."""
    n = worse + better
    tail = sum(Fraction(math.comb(n, i), 2**n) for i in range(min(worse, better) + 1))
    return min(Fraction(1), 2 * tail)


@pytest.mark.parametrize(
    ("worse", "better"), [(12, 2), (2, 12), (6, 16), (5, 5), (4, 0), (6, 0), (0, 0), (1, 30)]
)
def test_mcnemar_exact_is_exact_binomial_arithmetic(worse, better):
    assert mcnemar_exact(worse, better) == pytest.approx(
        float(exact_two_sided(worse, better)), rel=1e-15, abs=0
    )
    assert mcnemar_exact(12, 2) == 212 / 16384  # 2 (1 + 14 + 91) / 2^14, worked by hand


def test_mcnemar_of_4_and_6_one_way_flips():
    # why 4 of 150 going ok->failed is not significant and 6 is: 2/16 and 2/64
    assert mcnemar_exact(4, 0) == 0.125 and mcnemar_exact(6, 0) == 0.03125


def test_the_binomial_tail_in_logs_matches_exact_integers_beyond_the_exact_range():
    n = EXACT_UP_TO + 501
    for k in (n // 2 - 80, n // 2 - 1, n // 2, n // 2 + 40):
        exact = Fraction(sum(math.comb(n, i) for i in range(k + 1)), 2**n)
        assert half_binomial_cdf(k, n) == pytest.approx(float(exact), rel=1e-10)
    assert half_binomial_cdf(-1, n) == 0.0 and half_binomial_cdf(n, n) == 1.0


def test_median_interval_takes_the_sign_test_order_statistics():
    # n = 20: the 6th and 15th ordered values (2 P(X <= 5) = 0.0414 <= 0.05 < 2 P(X <= 6) = 0.1153)
    assert float(2 * sum(Fraction(math.comb(20, i), 2**20) for i in range(6))) < 0.05
    assert float(2 * sum(Fraction(math.comb(20, i), 2**20) for i in range(7))) > 0.05
    values = np.array(
        [
            3.0,
            -1.0,
            7.5,
            2.0,
            0.0,
            4.0,
            9.0,
            -2.5,
            1.0,
            6.0,
            5.0,
            8.0,
            -0.5,
            2.5,
            3.5,
            11.0,
            4.5,
            1.5,
            0.5,
            10.0,
        ]
    )
    med, lo, hi = median_ci(values)
    ordered = sorted(values)
    assert (med, lo, hi) == (float(np.median(values)), ordered[5], ordered[14])
    assert median_ci(np.array([])) is None
    assert median_ci(np.array([1.0, 2.0, 3.0])) == (2.0, 1.0, 3.0)  # too few: the range
    assert median_ci(np.zeros(50)) == (0.0, 0.0, 0.0)  # nothing moved: no shift


def _side(label, ok, placement, x, errors=None):
    n = len(ok)
    table = pa.table(
        {
            "scenario": pa.array(range(n), pa.int64()),
            "box.x_m": pa.array(x),
            "outcome": ["ok" if o else "error" for o in ok],
            "error": errors
            or ["" if o else "suction on at (0.2, 0.7), nothing sensed" for o in ok],
            "placement_error_mm": pa.array(placement, pa.float64()),
        }
    )
    return paired.side_from_table(table, label)


def test_pair_counts_flips_both_ways_and_names_them():
    ok_a = [True] * 8 + [False] * 2
    ok_b = [True, False, True, True, True, True, False, True, True, False]  # 2 worse, 1 better
    pe_a = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, None, None]
    pe_b = [1.5, None, 3.5, 4.5, 5.5, 6.5, None, 8.5, 2.0, None]
    x = [0.19 + 0.002 * i for i in range(10)]
    p = paired.pair(_side("a", ok_a, pe_a, x), _side("b", ok_b, pe_b, x))
    assert (p.n, p.both_ok, p.worse, p.better, p.neither_ok) == (10, 6, 2, 1, 1)
    assert [f.scenario for f in p.worse_flips] == [1, 6] and [
        f.scenario for f in p.better_flips
    ] == [8]
    assert p.worse_flips[0].values == {"box.x_m": pytest.approx(0.192)}
    assert p.worse_flips[0].reason_now == "suction on at (0.2, 0.7), nothing sensed"
    assert p.difference == pytest.approx(-0.1) and p.mcnemar_p == 1.0
    assert p.interval == newcombe_paired(6, 1, 2, 1)
    assert p.shift == (0.5, 0.5, 0.5) and p.shift_count == 6 and p.placed_changed == 3
    assert p.values_moved == {}
    text = paired.report_text(p, "d.toml")
    assert (
        "ok->failed 2, failed->ok 1" in text
        and "scenario 1: box.x_m=0.192; now: suction on" in text
    )
    assert "twin sweep d.toml --only 1 --out runs/s1" in text
    assert paired.problems(p, "significant", 0.5) == []
    strict = paired.problems(p, "strict", 0.5)
    assert (
        strict[0]
        == "3 scenarios flipped (strict: any flip fails): ok->failed 2 (1, 6), failed->ok 1 (8)"
    )
    assert paired.problems(p, "strict", 0.4)[-1].startswith(
        "placement error moved beyond 0.4 mm in 6 "
    )


def test_a_significant_one_way_drop_fails_the_significant_rule():
    n = 300
    ok_a = [i % 50 != 0 for i in range(n)]  # 294 ok
    ok_b = [o and i not in (1, 2, 3, 4, 5, 7) for i, o in enumerate(ok_a)]  # 6 go ok -> failed
    pe = [1.0] * n
    x = [0.2] * n
    p = paired.pair(_side("a", ok_a, pe, x), _side("b", ok_b, pe, x))
    assert (p.worse, p.better, p.mcnemar_p) == (6, 0, 0.03125)
    [problem] = paired.problems(p, "significant", 0.5)
    assert problem.startswith("success rate dropped significantly: 98.00 % -> 96.00 %")
    assert p.interval[1] < 0  # Newcombe's paired interval agrees: below 0
