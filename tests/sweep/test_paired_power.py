"""The power of the paired verdict (twin.sweep.power) against values computed another way: the
verdict itself (paired.pair and paired.problems) over every outcome of a few scenarios, weighted by
exact multinomial probabilities; McNemar's exact test (stats.mcnemar_exact) for the critical
counts; exact integer binomial sums for the one-way case; a normal approximation at 100k
scenarios; random draws. Then what a user sees: `twin sweep compare` of 150 scenarios where 4 went
ok -> failed, and the definition's success_drop_pct."""

from __future__ import annotations

import functools
import json
import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from twin.cli.main import main
from twin.model.errors import ConfigError
from twin.sweep import paired, power
from twin.sweep.spec import SweepSpec
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


def one_way_exact(n: int, drop: Fraction) -> Fraction:
    """P(Binomial(n, drop) >= 6) in fractions: 6 one-way flips are significant, 5 are not."""
    return 1 - sum(math.comb(n, k) * drop**k * (1 - drop) ** (n - k) for k in range(6))


def test_150_scenarios_cannot_see_a_drop_of_4_one_way_flips(tmp_path, capsys):
    pct = power.detectable_drop_pct(150, 4)
    assert pct > 100 * 4 / 150  # 2.67 points: below what 150 scenarios detect
    drop = Fraction(pct).limit_denominator(10**12) / 100
    assert one_way_exact(150, drop + Fraction(1, 10**8)) >= Fraction(4, 5)
    assert one_way_exact(150, drop - Fraction(1, 10**8)) < Fraction(4, 5)
    a, b = _folders(tmp_path, 150, 4, "[tolerance]\nsuccess_drop_pct = 2.67\n")
    capsys.readouterr()
    assert main(["sweep", "compare", str(a), str(b), "--report", str(tmp_path / "r.json"),
                 "--fail-if-worse"]) == 0  # p = 0.125: not significant, so not failed
    out = capsys.readouterr().out
    assert "ok->failed 4, failed->ok 0" in out and "McNemar exact p = 0.125" in out
    assert "detects drops of 5.3 points or more at 80 % power (150 scenarios, alpha 0.05)" in out
    needed = power.scenarios_to_detect(2.67, 4 / 150)
    assert (f"warning: success_drop_pct 2.67 is below the detectable drop (5.3 points at 80 % "
            f"power with 150 scenarios): about {needed} scenarios would detect a 2.67-point drop"
            in out)
    assert "warning: the measured drop, 2.67 points, is beyond success_drop_pct 2.67" not in out
    # a 2.67-point drop with no more flips than that (all one-way): its scenarios, exactly
    assert one_way_exact(needed, Fraction(267, 10000)) >= Fraction(4, 5)
    assert one_way_exact(needed - 1, Fraction(267, 10000)) < Fraction(4, 5)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["detectable_drop_pct"] == pct and len(report["warnings"]) == 1
    assert main(["sweep", "compare", str(a), str(b), "--report", str(tmp_path / "r.md")]) == 0
    markdown = (tmp_path / "r.md").read_text()
    assert "The verdict detects drops of 5.3 points or more at 80 % power" in markdown
    assert "- warning: success_drop_pct 2.67 is below the detectable drop" in markdown


def test_a_measured_drop_beyond_the_threshold_is_named_but_fails_only_if_significant(
        tmp_path, capsys):
    a, b = _folders(tmp_path, 150, 4, "[tolerance]\nsuccess_drop_pct = 2\n")
    capsys.readouterr()
    assert main(["sweep", "compare", str(a), str(b), "--fail-if-worse"]) == 0
    assert ("warning: the measured drop, 2.67 points, is beyond success_drop_pct 2 but not "
            "significant (McNemar exact p = 0.125): it does not fail the significant rule"
            in capsys.readouterr().out)
    a, b = _folders(tmp_path / "six", 150, 6, "[tolerance]\nsuccess_drop_pct = 2\n")
    assert main(["sweep", "compare", str(a), str(b), "--fail-if-worse"]) == 1  # p = 0.031
    assert "success rate dropped significantly" in capsys.readouterr().err


def _folders(folder, n: int, worse: int, tolerance: str):
    """Result folders a (reference) and b (new) of n scenarios, `worse` of them ok -> failed."""
    for name, ok in (("a", [True] * n), ("b", [i >= worse for i in range(n)])):
        (folder / name).mkdir(parents=True)
        pq.write_table(_side(name, ok).table, folder / name / "results.parquet")
        (folder / name / "sweep.toml").write_text(
            f'task = "pick_place"\nseed = 1\nscenarios = {n}\n\n[vary]\n'
            f'"box.x_m" = "normal(0.2, 0.012)"\n\n{tolerance}')
    return folder / "a", folder / "b"


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


def test_strict_detects_one_flip_and_the_threshold_warns_below_it():
    p = _flipped(150, 0, 0)
    assert power.detectable_text(150, p.detectable_drop_pct, "strict") == (
        "detects a drop of one flip, 0.67 points (150 scenarios; strict: any flip fails)")
    assert paired.warnings(p, "strict", 1.0) == []
    [warning] = paired.warnings(p, "strict", 0.5)
    assert warning == ("success_drop_pct 0.5 is below the detectable drop (one flip, 0.67 points "
                       "with 150 scenarios): 200 scenarios would make one flip a 0.5-point drop")


@pytest.mark.parametrize("value", [0, -1, 100.5, float("nan"), float("inf"), True, "3"])
def test_success_drop_pct_is_points_above_0(value):
    with pytest.raises(ConfigError) as err:
        SweepSpec(task="pick_place", scenarios=10, tolerance={"success_drop_pct": value})
    assert str(err.value).startswith(f"tolerance success_drop_pct = {value!r} is invalid; "
                                     "expected the drop in success rate that matters, in "
                                     "percentage points: a number > 0 and <= 100")
    assert "\n" not in str(err.value)


def test_the_docs_table_of_scenarios_is_what_the_code_computes():
    page = (Path(__file__).resolve().parents[2] / "docs" / "how-to" / "paired-sweeps.md")
    block = page.read_text().split('title="measured: python tools/sweep_power.py table"')[1]
    rows = re.findall(r"^ +([\d.]+)p +([\d.]+)% +(\d+) +([\d.]+) +[\d.]+$",
                      block.split("```")[0], re.MULTILINE)
    assert len(rows) == 9
    for drop_pct, flipped_pct, scenarios, computed in rows:
        share = float(flipped_pct) / 100
        assert power.scenarios_to_detect(float(drop_pct), share) == int(scenarios)
        assert f"{power.drop_power(int(scenarios), share, float(drop_pct) / 100):.3f}" == computed
