"""How many scenarios a paired verdict needs to find a drop in success rate: computed
(twin.sweep.power), drawn at random and resampled from two real sweeps. The figures quoted in
docs/how-to/paired-sweeps.md come from here.

    python tools/sweep_power.py table [--draws N]
        for drops of 2, 2.5 and 3 points, with no other flips and with other flips both ways
        (a discordance of 5 and 10 %): the scenarios the "significant" rule needs for 80 % power,
        and how often it failed over N random draws of that many scenarios (each scenario flips
        ok->failed or failed->ok at random; judged by McNemar's exact test as the verdict is).
        Then the user's case, 150 scenarios and a 2.67-point one-way drop, and how often a rule
        that failed on a measured drop beyond 2 points would fail 150 scenarios with no drop.
    python tools/sweep_power.py resample A B [--sizes 150,300] [--draws N]
        A and B are result folders of the same scenarios (twin sweep --out) where B has a drop:
        n of their scenario pairs drawn with replacement, N times, each draw judged by
        twin.sweep.paired (pair, problems "significant"), against the power computed for n.
"""

from __future__ import annotations

import argparse
import functools
import sys

import numpy as np
import pyarrow as pa

from twin.model.errors import ConfigError
from twin.sweep import paired, power
from twin.sweep.stats import mcnemar_exact

SEED = 2026  # the draws' seed: the figures are the same each run
DROPS_PCT = (2.0, 2.5, 3.0)
DISCORDANCES = (0.0, 0.05, 0.10)  # the share of scenarios flipped either way (at least the drop)


@functools.cache
def fails(worse: int, better: int) -> bool:
    """The "significant" rule's verdict on the success rate (paired.problems): more ok->failed
    and McNemar's exact p < 0.05."""
    return worse > better and mcnemar_exact(worse, better) < paired.ALPHA


def drawn_rate(n: int, discordance: float, drop: float, draws: int, rng) -> float:
    """How often the verdict fails over `draws` random sets of n scenarios."""
    share = max(discordance, drop)
    counts = rng.multinomial(n, [(share + drop) / 2, (share - drop) / 2, 1 - share], size=draws)
    return float(np.mean([fails(int(w), int(b)) for w, b, _ in counts]))


def table(draws: int) -> None:
    rng = np.random.default_rng(SEED)
    print(f"{'drop':>6} {'flipped':>7} {'scenarios':>9} {'computed':>9} {'drawn':>7}")
    for drop_pct in DROPS_PCT:
        for discordance in DISCORDANCES:
            share = max(discordance, drop_pct / 100)
            n = power.scenarios_to_detect(drop_pct, share)
            computed = power.drop_power(n, share, drop_pct / 100)
            drawn = drawn_rate(n, share, drop_pct / 100, draws, rng)
            print(f"{drop_pct:5.1f}p {100 * share:6.1f}% {n:9d} {computed:9.3f} {drawn:7.3f}")
    n, drop = 150, 4 / 150
    drawn = drawn_rate(n, drop, drop, draws, rng)
    print(f"150 scenarios, a {100 * drop:.2f}-point one-way drop: computed "
          f"{power.drop_power(n, drop, drop):.3f}, drawn {drawn:.3f}; detectable "
          f"{power.detectable_drop_pct(n, 4):.2f} points")
    counts = rng.multinomial(n, [0.02, 0.02, 0.96], size=draws)  # 4 % flipped, no drop
    beyond = np.mean([(w - b) / n > 0.02 for w, b, _ in counts])
    significant = np.mean([fails(int(w), int(b)) for w, b, _ in counts])
    print(f"150 scenarios, 4 % flipped both ways, no drop: measured drop beyond 2 points in "
          f"{beyond:.3f} of {draws} draws, significant in {significant:.3f}")


def _renumbered(side: paired.Side, rows: np.ndarray, label: str) -> paired.Side:
    table = side.table.take(pa.array(rows))
    table = table.set_column(0, "scenario", pa.array(np.arange(len(rows), dtype=np.int64)))
    return paired.side_from_table(table, label)


def resample(a: str, b: str, sizes: list[int], draws: int) -> None:
    reference, new = paired.read_side(f"{a}/results.parquet"), paired.read_side(
        f"{b}/results.parquet")
    whole = paired.pair(reference, new)
    if whole.only_reference or whole.only_new:
        sys.exit(f"{a} and {b} hold other scenarios; expected sweeps of the same ones")
    share, drop = (whole.worse + whole.better) / whole.n, (whole.worse - whole.better) / whole.n
    print(f"{whole.n} pairs: ok->failed {whole.worse}, failed->ok {whole.better}, a drop of "
          f"{100 * drop:.2f} points; 80 % power from about "
          f"{power.scenarios_to_detect(100 * drop, share)} scenarios")
    rng = np.random.default_rng(SEED)
    for n in sizes:
        failed = 0
        for _ in range(draws):
            rows = rng.integers(0, whole.n, n)
            p = paired.pair(_renumbered(reference, rows, "a"), _renumbered(new, rows, "b"))
            failed += bool(paired.problems(p, "significant", 0.5))
        print(f"{n:6d} scenarios: failed {failed / draws:.3f} of {draws} draws, computed "
              f"{power.drop_power(n, share, drop):.3f}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("table").add_argument("--draws", type=int, default=20_000)
    again = sub.add_parser("resample")
    again.add_argument("a")
    again.add_argument("b")
    again.add_argument("--sizes", default="150,200,300,400")
    again.add_argument("--draws", type=int, default=2_000)
    args = parser.parse_args(argv)
    if args.draws < 1:
        parser.error(f"--draws {args.draws} is invalid; expected a whole number >= 1")
    if args.what == "table":
        table(args.draws)
        return
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        parser.error(f"--sizes {args.sizes!r} is invalid; expected whole numbers, e.g. 150,300")
    if min(sizes) < 1:
        parser.error(f"--sizes {args.sizes!r} is invalid; expected whole numbers >= 1")
    resample(args.a, args.b, sizes, args.draws)


if __name__ == "__main__":
    try:
        main()
    except ConfigError as err:
        sys.exit(f"sweep_power: error: {err}")
