"""The power of a paired verdict: the smallest drop in success rate that the "significant" rule
(paired.problems: McNemar's exact two-sided p < ALPHA with more ok->failed than failed->ok) finds
with probability POWER at a given number of scenarios.

The model. Each of n scenarios flips ok->failed with probability p_worse and failed->ok with
p_better, independently; the drop is delta = p_worse - p_better, the discordance
psi = p_worse + p_better. psi is the comparison's own: its observed share of flips either way,
raised to delta when smaller (a drop of delta needs at least that many flips; with no flip
observed the best case is every flip one-way, psi = delta). The flips D ~ Binomial(n, psi); given
D = d, the failed->ok ones B ~ Binomial(d, r), r = p_better / psi = (psi - delta) / (2 psi). The
verdict fails exactly when B <= m(d), the largest count with 2 P(Binomial(d, 1/2) <= m) < ALPHA
(-1 when none: below MIN_FLIPS flips nothing is significant). So

    power(delta) = sum over d of P(D = d) P(Binomial(d, r) <= m(d)),

summed over the d within WINDOW standard deviations and SLACK counts of D's mean (what is left
out held less than 1e-26 for n from 6 to 100k and psi from 1e-7 to 0.999). Both factors are
exact binomial sums: m(d) by stepping Binomial(d, 1/2)'s distribution function from one d to the
next (F(m; d+1) = F(m; d) - f(m; d) / 2), the second factor by the same step at r, taken for all
d at once (a cumulative sum of its steps); the probabilities come from log-factorials. When
r = 0 (every flip one-way) the verdict fails exactly when D >= MIN_FLIPS.

The power grows with delta, so the detectable drop is found by bisection (to BISECT_TOL, a share
of the scenarios) and given in percentage points. Each step costs a few vector operations over
the d window (about 24 standard deviations of D wide); m(d) is stepped once, in Python. The whole
of detectable_drop_pct: 3 ms for 100k scenarios with 1 % flipped, 0.4 s for 10M with half.
"""

from __future__ import annotations

import math

import numpy as np

ALPHA = 0.05  # the "significant" rule's level (paired.ALPHA)
POWER = 0.80  # the probability of failing the verdict that makes a drop "detectable"
WINDOW, SLACK = 12.0, 12  # D's window: mean +- WINDOW standard deviations, +- SLACK flips
BISECT_TOL = 1e-9  # the detectable drop's precision (a share of the scenarios)
MAX_SCENARIOS = 10_000_000  # the largest sweep (spec.MAX_SCENARIOS): beyond it, "more than"
_TABLE = 1024  # log k! from math.lgamma below this, Stirling's series from it on
_LOG_FACT = np.array([math.lgamma(k + 1.0) for k in range(_TABLE)])


def min_flips(alpha: float = ALPHA) -> int:
    """The fewest flips, all one-way, that are significant: 2 / 2**d < alpha (6 at 0.05)."""
    d = 1
    while 2.0 * 0.5**d >= alpha:
        d += 1
    return d


MIN_FLIPS = min_flips()


def log_factorial(k: np.ndarray) -> np.ndarray:
    """log(k!) for whole numbers k >= 0 (an array): a table of math.lgamma below _TABLE, beyond it
    Stirling's series to 1/k**5 (its error below 1e-20 there)."""
    k = np.asarray(k, dtype=np.int64)
    out = np.empty(k.shape, dtype=float)
    small = k < _TABLE
    out[small] = _LOG_FACT[k[small]]
    x = k[~small].astype(float)
    inv = 1.0 / x
    inv2 = inv * inv
    out[~small] = (x * np.log(x) - x + 0.5 * np.log(2.0 * math.pi * x)
                   + inv * (1.0 / 12 - inv2 * (1.0 / 360 - inv2 / 1260)))
    return out


def log_binomial_pmf(k: np.ndarray, n: np.ndarray | int, p: float) -> np.ndarray:
    """log P(Binomial(n, p) = k) for 0 <= k <= n (arrays), 0 <= p <= 1 (-inf: impossible)."""
    k, n = np.asarray(k, dtype=np.int64), np.asarray(n, dtype=np.int64)
    log_p = math.log(p) if p > 0.0 else -math.inf
    log_q = math.log1p(-p) if p < 1.0 else -math.inf
    return (log_factorial(n) - log_factorial(k) - log_factorial(n - k)
            + _times(k, log_p) + _times(n - k, log_q))


def _times(count: np.ndarray, log_p: float) -> np.ndarray:
    """count * log_p, and 0 where count is 0 (also when log_p is -inf: p = 0)."""
    if math.isfinite(log_p):
        return count * log_p
    return np.where(count > 0, -math.inf, 0.0)


def binomial_window(n: int, p: float) -> tuple[int, int]:
    """The counts lo..hi that hold all of Binomial(n, p)'s probability but a negligible tail."""
    mean, sd = n * p, math.sqrt(n * p * (1.0 - p))
    return max(0, math.floor(mean - WINDOW * sd) - SLACK), min(n, math.ceil(mean + WINDOW * sd)
                                                                   + SLACK)


def _half_cdf_at(d: int, alpha: float) -> tuple[int, float]:
    """(m(d), F(m(d); d)) for Binomial(d, 1/2): the largest m with 2 F(m; d) < alpha, summed over
    the lower window of the distribution (m = -1, F = 0 when there is none)."""
    lo, _ = binomial_window(d, 0.5)
    k = np.arange(lo, d // 2 + 1)
    cdf = np.cumsum(np.exp(log_binomial_pmf(k, d, 0.5)))
    below = np.flatnonzero(2.0 * cdf < alpha)
    if below.size == 0:
        return -1, 0.0
    return int(k[below[-1]]), float(cdf[below[-1]])


def critical_better(d_lo: int, d_hi: int, alpha: float = ALPHA) -> np.ndarray:
    """m(d) for d = d_lo..d_hi: the most failed->ok flips of d with which d - m ok->failed ones
    are significant (McNemar exact, two-sided, p < alpha); -1 when no split of d is. m(d+1) is
    m(d) or m(d) + 1, so F(m; d) and the probabilities at m and m + 1 are stepped along d."""
    out = np.empty(d_hi - d_lo + 1, dtype=np.int64)
    m, cdf = _half_cdf_at(d_lo, alpha)
    d = d_lo
    f_m = math.exp(log_binomial_pmf(m, d, 0.5)) if m >= 0 else 0.0  # f(m; d)
    f_next = math.exp(log_binomial_pmf(m + 1, d, 0.5))  # f(m + 1; d): m < d / 2 always
    out[0] = m
    for i in range(1, len(out)):
        # one more flip: F(m; d+1) = F(m; d) - f(m; d)/2, f(j; d+1) = f(j; d) (d+1) / 2 (d+1-j)
        cdf -= 0.5 * f_m
        f_m = f_m * (d + 1) / (2.0 * (d + 1 - m)) if m >= 0 else 0.0
        f_next = f_next * (d + 1) / (2.0 * (d - m))
        d += 1
        if 2.0 * (cdf + f_next) < alpha:
            m, cdf, f_m = m + 1, cdf + f_next, f_next
            f_next = f_m * (d - m) / (m + 1)
        out[i] = m
    return out


class Flips:
    """The exact power of the "significant" rule over n scenarios whose flips either way make
    the share `discordance`, for drops up to that share (r > 0): D's window, its probabilities
    and m(d) are computed once, each drop's power in a few vector operations."""

    def __init__(self, n: int, discordance: float, alpha: float = ALPHA) -> None:
        self.n, self.discordance = n, discordance
        self.d_lo, d_hi = binomial_window(n, discordance)
        self.d = np.arange(self.d_lo, d_hi + 1)
        self.p_d = np.exp(log_binomial_pmf(self.d, n, discordance))
        self.m = critical_better(self.d_lo, d_hi, alpha)
        self.ok = self.m >= 0
        m = np.where(self.ok, self.m, 0)
        self.log_comb = log_factorial(self.d) - log_factorial(m) - log_factorial(self.d - m)
        self.step_up = np.diff(self.m) > 0  # m(d+1) = m(d) + 1

    def power(self, drop: float) -> float:
        """P(the verdict fails) when the true drop is `drop` (a share, 0 <= drop <= discordance)."""
        r = (self.discordance - drop) / (2.0 * self.discordance)
        if r <= 0.0:
            return float(self.p_d[self.ok].sum())
        m = np.where(self.ok, self.m, 0)
        g = np.where(self.ok, np.exp(self.log_comb + m * math.log(r)
                                     + (self.d - m) * math.log1p(-r)), 0.0)  # P(B = m(d) | d)
        # P(B <= m(d+1) | d+1) - P(B <= m(d) | d) = -r g(d) + g(d+1) when m stepped up
        steps = -r * g[:-1] + np.where(self.step_up, g[1:], 0.0)
        first = self._first_cdf(r)
        cdf = np.clip(np.concatenate(([first], first + np.cumsum(steps))), 0.0, 1.0)
        return float(np.dot(self.p_d, cdf))

    def _first_cdf(self, r: float) -> float:
        """P(Binomial(d_lo, r) <= m(d_lo)), summed over its window."""
        m = int(self.m[0])
        if m < 0:
            return 0.0
        lo, hi = binomial_window(self.d_lo, r)
        k = np.arange(lo, min(m, hi) + 1)
        return float(np.exp(log_binomial_pmf(k, self.d_lo, r)).sum()) if k.size else 0.0


def one_way_power(n: int, drop: float, alpha: float = ALPHA) -> float:
    """P(the verdict fails) when every flip is one-way (ok->failed with probability drop): at
    least min_flips(alpha) of n."""
    if drop >= 1.0:
        return 1.0 if n >= min_flips(alpha) else 0.0
    k = np.arange(0, min(n, min_flips(alpha) - 1) + 1)
    return float(max(0.0, 1.0 - np.exp(log_binomial_pmf(k, n, drop)).sum())) if drop > 0 else 0.0


def drop_power(n: int, discordance: float, drop: float, alpha: float = ALPHA) -> float:
    """P(the "significant" rule fails) over n scenarios when the success rate truly drops by
    `drop` (a share) and the flips either way make the share max(discordance, drop)."""
    if n < min_flips(alpha):
        return 0.0
    if drop >= discordance:
        return one_way_power(n, drop, alpha)
    return Flips(n, discordance, alpha).power(drop)


def detectable_drop_pct(n: int, discordant: int, alpha: float = ALPHA,
                        power: float = POWER) -> float | None:
    """The smallest drop in success rate, in percentage points, that the "significant" rule finds
    with probability `power` over n scenarios of which `discordant` flipped either way. None when
    no drop can be found (fewer than min_flips(alpha) scenarios)."""
    if n < min_flips(alpha):
        return None
    share = discordant / n
    if share > 0.0:
        flips = Flips(n, share, alpha)
        if flips.power(share) >= power:  # found within the observed discordance
            return 100.0 * _bisect(flips.power, 0.0, share, power)
    # beyond the observed discordance every flip is one-way: the same answer whatever share was
    return 100.0 * _bisect(lambda drop: one_way_power(n, drop, alpha), 0.0, 1.0, power)


def _bisect(power_of, lo: float, hi: float, power: float) -> float:
    """The smallest drop in (lo, hi] whose power_of(drop) >= power (power_of(hi) is), to
    BISECT_TOL."""
    while hi - lo > BISECT_TOL:
        mid = 0.5 * (lo + hi)
        if power_of(mid) >= power:
            hi = mid
        else:
            lo = mid
    return hi


def scenarios_to_detect(drop_pct: float, discordance: float, alpha: float = ALPHA,
                        power: float = POWER) -> int | None:
    """About how many scenarios the "significant" rule needs to find a drop of drop_pct points
    with probability `power`, when the share `discordance` of them flip either way: the n where
    the power crosses `power` (bisected over n; it grows with n). None beyond MAX_SCENARIOS."""
    drop = drop_pct / 100.0
    if drop <= 0.0:
        return None

    def enough(n: int) -> bool:
        return drop_power(n, discordance, drop, alpha) >= power

    if not enough(MAX_SCENARIOS):
        return None
    lo, hi = min_flips(alpha) - 1, min_flips(alpha)
    while not enough(hi):
        lo, hi = hi, min(MAX_SCENARIOS, 2 * hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if enough(mid):
            hi = mid
        else:
            lo = mid
    return hi


def points_text(drop_pct: float) -> str:
    """A drop in points as said: rounded up (the statement "or more" stays true), to 0.1 from 1
    point on, to two significant figures below."""
    if drop_pct >= 1.0:
        return f"{math.ceil(drop_pct * 10 - 1e-9) / 10:.1f}"
    scale = 10.0 ** (1 - math.floor(math.log10(drop_pct)))
    return f"{math.ceil(drop_pct * scale - 1e-9) / scale:g}"


def rule_drop_pct(n: int, detectable_pct: float | None, rule: str) -> float | None:
    """The drop a verdict under rule detects: one flip (100 / n points) under "strict", which fails
    on any flip; the detectable drop at POWER under "significant"."""
    return 100.0 / n if rule == "strict" and n else detectable_pct


def detectable_text(n: int, detectable_pct: float | None, rule: str = "significant") -> str:
    """The verdict's power in one line."""
    if rule == "strict":
        return (f"detects a drop of one flip, {points_text(100.0 / n)} points ({n} scenarios; "
                "strict: any flip fails)")
    if detectable_pct is None:
        return (f"detects no drop at all: {n} scenarios, fewer than the {MIN_FLIPS} one-way flips "
                f"McNemar's exact test needs at alpha {ALPHA:g}")
    return (f"detects drops of {points_text(detectable_pct)} points or more at "
            f"{100 * POWER:.0f} % power ({n} scenarios, alpha {ALPHA:g})")


def threshold_warning(threshold_pct: float, n: int, discordant: int,
                      detectable_pct: float | None, rule: str = "significant") -> str | None:
    """A warning when the drop the definition cares about (success_drop_pct) is below what the
    verdict detects, saying how many scenarios would detect it; None when it is not."""
    drop_pct = rule_drop_pct(n, detectable_pct, rule)
    if drop_pct is not None and threshold_pct >= drop_pct:
        return None
    if drop_pct is None:
        said = "none"
    elif rule == "strict":
        said = f"one flip, {points_text(drop_pct)} points"
    else:
        said = f"{points_text(drop_pct)} points at {100 * POWER:.0f} % power"
    head = (f"success_drop_pct {threshold_pct:g} is below the detectable drop ({said} with {n} "
            "scenarios)")
    if rule == "strict":
        needed = math.ceil(100.0 / threshold_pct - 1e-9)
        return f"{head}: {needed:,} scenarios would make one flip a {threshold_pct:g}-point drop"
    needed = scenarios_to_detect(threshold_pct, discordant / n if n else 0.0)
    if needed is None:
        return f"{head}: more than {MAX_SCENARIOS:,} scenarios would be needed to detect it"
    return f"{head}: about {needed:,} scenarios would detect a {threshold_pct:g}-point drop"
