"""Search for the smallest perturbation that breaks a task (`twin search`), its rounds fanned out
through `twin.jobs` (a round's points are a `Probes` unit).

Each searched key has a range LOW..HIGH around its nominal value (the scene's, the pad's, the
robot's or the task's default). A scenario's size is measured in each key's own scale: the sum over
keys of |value - nominal| / half-width, half-width being (HIGH - LOW) / 2. The search runs in
rounds; a round's scenarios depend only on the results of earlier rounds, never on the job count
or the order results come back, so the outcome is the same on 1 or N local workers and on Dask:

1. the nominal scenario and each key's two range ends (the others nominal);
2. the boundary along each key: bisection between the nominal (passing) and a failing end, on
   both sides at once, until the bracket is at most the key's precision;
3. exploration: seeded uniform draws over the whole box (RandomSampler, as a sweep draws);
4. shrinking: the smallest failure of each reason moves toward nominal, one key at a time (first
   to nominal, then by bisection), until no key's offset can shrink by its precision and still fail.

Every run counts against the budget; a search stopped by the budget or by Ctrl-C keeps what it
found (`SearchResult.stopped`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from twin.jobs.guard import run_batch_guarded
from twin.search.keys import DEFAULT_PRECISION, Range, prepare_search
from twin.signals import Terminated
from twin.sweep.dists import Dist
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import SweepSpec
from twin.sweep.stats import reason
from twin.sweep.worker import Job

__all__ = [
    "DEFAULT_PRECISION",
    "Probes",
    "Range",
    "Search",
    "SearchResult",
    "prepare_search",
    "probe_spec",
    "result_json",
    "run_probe",
]

EXPLORE_MAX = (
    16  # seeded draws over the whole box, at most (and at most a third of the budget left)
)
EXPLORE_ROUND = 8  # draws per round: a fixed number, so the rounds do not depend on the job count
SHRINK_MAX = 3  # failures shrunk: the smallest of each reason, at most this many
SHRINK_PASSES = 3  # passes over the keys while a pass still moves one
SIZE_TEXT = "sum over keys of |value - nominal| / half-width, half-width = (high - low) / 2"


class BudgetSpent(Exception):
    """The search has used its budget of runs."""


@dataclass(frozen=True)
class Probe:
    """One run's values (in the ranges' order) and its result."""

    values: tuple[float, ...]
    outcome: str
    error: str

    @property
    def failed(self) -> bool:
        return self.outcome != "ok"

    @property
    def reason(self) -> str:
        return reason(self.error) if self.failed else ""


@dataclass
class Side:
    """The boundary on one side of a key: `passing` nearer nominal, `failing` beyond (None: the
    range's end passes)."""

    passing: float
    failing: float | None

    def width(self) -> float:
        return math.inf if self.failing is None else abs(self.failing - self.passing)


@dataclass
class SearchResult:
    """What a search found; `stopped` is None, "budget" or "interrupted"."""

    spec: SweepSpec
    ranges: tuple[Range, ...]
    budget: int
    runs: int = 0
    nominal: Probe | None = None
    sides: dict[tuple[str, str], Side] = field(default_factory=dict)
    failures: list[Probe] = field(default_factory=list)  # every failing run, in the order run
    shrunk: list[Probe] = field(default_factory=list)
    stopped: str | None = None

    def size(self, values: Sequence[float]) -> float:
        return sum(
            abs(v - r.nominal) / r.half_width for v, r in zip(values, self.ranges, strict=True)
        )

    @property
    def minimal(self) -> Probe | None:
        """The smallest failure known: among the shrunk ones, else among all that failed."""
        pool = self.shrunk or self.failures
        return min(pool, key=lambda p: (self.size(p.values), p.reason, p.values), default=None)

    def boundary(self, r: Range) -> dict | None:
        """The key's boundary on its nearer failing side (the low side on a tie), as search.json
        has it."""
        low, high = self.sides.get((r.name, "low")), self.sides.get((r.name, "high"))
        if low is None or high is None:
            return None
        near = min(
            ((low, "low"), (high, "high")),
            key=lambda s: (s[0].failing is None, abs((s[0].failing or 0) - r.nominal)),
        )
        side, which = near
        return {
            "passing": side.passing,
            "failing": side.failing,
            "precision": r.precision,
            "side": which,
            "width": None if side.failing is None else side.width(),
            "converged": _converged(side, r),
            "low": _side_json(low, r),
            "high": _side_json(high, r),
        }


def _converged(side: Side, r: Range) -> bool:
    """Found to the key's precision (or no failure on that side: the range's end passes)."""
    return side.failing is None or side.width() <= r.precision


def _side_json(side: Side, r: Range) -> dict:
    return {"passing": side.passing, "failing": side.failing, "converged": _converged(side, r)}


def probe_spec(spec: SweepSpec, names: Sequence[str], values: Sequence[float]) -> SweepSpec:
    """A one-scenario definition that runs exactly these values of the named keys (constants,
    written exactly)."""
    vary = tuple((name, repr(float(v))) for name, v in zip(names, values, strict=True))
    return dataclasses.replace(spec, scenarios=1, vary=vary)


@dataclass(frozen=True)
class Probes:
    """A round's points as a `twin.jobs` unit: item i runs the one scenario of specs[i] (a
    constant-valued definition), recording nothing; its result is (outcome, error line)."""

    specs: tuple[SweepSpec, ...]

    def warm(self) -> None:
        if self.specs:  # the task resolved and twin imported before the children fork
            Job(self.specs[0], None, "none").warm()

    def run(self, item: int) -> tuple[str, str]:
        row = Job(self.specs[item], None, "none").run(0)
        return row["outcome"], row["error"]

    def confirm(self, item: int) -> tuple[str, str]:
        return self.run(item)

    def failed(self, item: int, reason: str, wall_s: float) -> tuple[str, str]:
        return "error", reason


def run_probe(spec: SweepSpec, timeout_s: float | None = None) -> tuple[str, str]:
    """One scenario (a constant-valued definition), in a guarded child: (outcome, error line)."""
    return run_batch_guarded(Probes((spec,)), [0], timeout_s)[0][1]


class Search:
    """The search's state: the runs so far (each set of values runs once) and the budget."""

    def __init__(
        self,
        spec: SweepSpec,
        ranges: tuple[Range, ...],
        executor,
        budget: int,
        *,
        timeout_s: float | None = None,
        progress: Callable[[str, SearchResult], None] | None = None,
    ) -> None:
        self.result = SearchResult(spec, ranges, budget)
        self.ranges, self.executor, self.timeout_s = ranges, executor, timeout_s
        self.progress = progress
        self.cache: dict[tuple[float, ...], Probe] = {}
        self.phase = ""

    def run(self) -> SearchResult:
        """The whole search; stops early (keeping what it found) on the budget or Ctrl-C."""
        res = self.result
        try:
            self._start()
            if res.nominal is not None and not res.nominal.failed:
                self._boundaries()
                self._explore()
                self._shrink_all()
        except BudgetSpent:
            res.stopped = "budget"
        except (KeyboardInterrupt, Terminated):
            res.stopped = "interrupted"
            if res.nominal is None:  # stopped between its round's end and _start reading it
                res.nominal = self.cache.get(self._nominal())
            self.executor.close()
            raise
        return res

    def evaluate(self, points: list[tuple[float, ...]]) -> list[Probe]:
        """Run the points not run before (one round, spread over the executor); BudgetSpent when the
        budget cannot hold them all (the round is not run: its size never depends on the budget left
        in a way the job count could change)."""
        new = list(dict.fromkeys(p for p in points if p not in self.cache))
        if self.result.runs + len(new) > self.result.budget:
            raise BudgetSpent
        names = [r.name for r in self.ranges]
        probes = Probes(tuple(probe_spec(self.result.spec, names, p) for p in new))
        for i, (outcome, error) in self.executor.map_unordered(probes, len(new), self.timeout_s):
            probe = Probe(new[i], outcome, error)
            self.cache[new[i]] = probe
        for p in new:  # in the round's order, not the order they finished
            self.result.runs += 1
            if self.cache[p].failed:
                self.result.failures.append(self.cache[p])
        if self.progress is not None:
            self.progress(self.phase, self.result)
        return [self.cache[p] for p in points]

    def _nominal(self) -> tuple[float, ...]:
        return tuple(r.nominal for r in self.ranges)

    def _with(self, base: tuple[float, ...], i: int, value: float) -> tuple[float, ...]:
        return base[:i] + (value,) + base[i + 1 :]

    def _start(self) -> None:
        self.phase = "nominal and range ends"
        nominal = self._nominal()
        points = [nominal]
        for i, r in enumerate(self.ranges):
            points += [self._with(nominal, i, r.low), self._with(nominal, i, r.high)]
        probes = self.evaluate(points)
        self.result.nominal = probes[0]
        if probes[0].failed:  # no boundary to find: the nominal scene is the smallest failure
            return
        for i, r in enumerate(self.ranges):
            for k, (end, which) in enumerate(((r.low, "low"), (r.high, "high"))):
                failed = probes[1 + 2 * i + k].failed
                self.result.sides[(r.name, which)] = (
                    Side(r.nominal, end) if failed else Side(end, None)
                )

    def _boundaries(self) -> None:
        """Bisect every side that has a failing end, all at once, round by round."""
        self.phase = "boundary"
        nominal = self._nominal()
        while True:
            todo = [
                (i, which, side)
                for i, r in enumerate(self.ranges)
                for which in ("low", "high")
                if (side := self.result.sides[(r.name, which)]).failing is not None
                and side.width() > r.precision
            ]
            if not todo:
                return
            mids = [
                self._with(nominal, i, (side.passing + side.failing) / 2) for i, _, side in todo
            ]
            for (i, _, side), probe in zip(todo, self.evaluate(mids), strict=True):
                if probe.failed:
                    side.failing = probe.values[i]
                else:
                    side.passing = probe.values[i]

    def _explore(self) -> None:
        """Seeded draws over the box, in rounds of EXPLORE_ROUND."""
        self.phase = "exploring"
        res = self.result
        count = min(EXPLORE_MAX, (res.budget - res.runs) // 3)
        sampler = RandomSampler(
            res.spec.seed, tuple((r.key, Dist("uniform", (r.low, r.high), "")) for r in self.ranges)
        )
        draws = [tuple(float(v) for v in sampler.values(s).values()) for s in range(count)]
        for k in range(0, count, EXPLORE_ROUND):
            self.evaluate(draws[k : k + EXPLORE_ROUND])

    def _shrink_all(self) -> None:
        """Shrink the smallest failure of each reason (at most SHRINK_MAX of them, smallest
        first)."""
        self.phase = "shrinking"
        res = self.result
        by_reason: dict[str, Probe] = {}
        for p in sorted(res.failures, key=lambda p: (res.size(p.values), p.reason, p.values)):
            by_reason.setdefault(p.reason, p)
        for start in sorted(by_reason.values(), key=lambda p: (res.size(p.values), p.reason))[
            :SHRINK_MAX
        ]:
            res.shrunk.append(start)  # known to fail: kept (and replaced) as the shrinking goes on
            self._shrink(start)

    def _shrink(self, probe: Probe) -> None:
        """Move the failure toward nominal while it still fails: each key to nominal (the best of a
        round), then each key's offset by bisection, until no key moves by more than its
        precision."""
        res = self.result
        current = probe
        for _ in range(SHRINK_PASSES):
            moved = False
            while True:  # keys that can go back to nominal altogether
                off = [i for i, r in enumerate(self.ranges) if current.values[i] != r.nominal]
                tries = self.evaluate(
                    [self._with(current.values, i, self.ranges[i].nominal) for i in off]
                )
                failing = [p for p in tries if p.failed]
                if not failing:
                    break
                current, moved = min(failing, key=lambda p: (res.size(p.values), p.values)), True
                res.shrunk[-1] = current
            for i, r in enumerate(self.ranges):
                before = current.values[i]
                current = self._bisect_key(current, i)
                res.shrunk[-1] = current
                moved = moved or abs(current.values[i] - before) > r.precision
            if not moved:
                return

    def _bisect_key(self, current: Probe, i: int) -> Probe:
        """current with key i's offset as small as it can be while still failing, to the key's
        precision: one run shows a failure already minimal (a precision nearer nominal passes)."""
        r = self.ranges[i]
        value = current.values[i]
        offset = value - r.nominal
        if abs(offset) <= r.precision:
            return current
        nearer = self.evaluate(
            [self._with(current.values, i, value - math.copysign(r.precision, offset))]
        )[0]
        if not nearer.failed:
            return current
        passing, failing = (
            r.nominal,
            nearer,
        )  # the key at nominal passed (or current would be there)
        while abs(failing.values[i] - passing) > r.precision:
            mid = self.evaluate([self._with(current.values, i, (passing + failing.values[i]) / 2)])[
                0
            ]
            if mid.failed:
                failing = mid
            else:
                passing = mid.values[i]
        return failing


def result_json(res: SearchResult) -> dict:
    """search.json's content."""
    minimal = res.minimal
    spec = res.spec

    def values(p: Probe) -> dict:
        return {r.name: v for r, v in zip(res.ranges, p.values, strict=True)}

    def failure(p: Probe) -> dict:
        return {
            "values": values(p),
            "reason": p.error,
            "kind": p.reason,
            "size": res.size(p.values),
        }

    return {
        "task": spec.task,
        "robot": spec.robot,
        "seed": spec.seed,
        "params": dict(sorted(spec.params.items())),
        "keys": {
            r.name: {
                "low": r.low,
                "high": r.high,
                "nominal": r.nominal,
                "half_width": r.half_width,
                "precision": r.precision,
            }
            for r in res.ranges
        },
        "size": SIZE_TEXT,
        "nominal": None
        if res.nominal is None
        else {"outcome": res.nominal.outcome, "reason": res.nominal.error},
        "minimal": None
        if minimal is None
        else {**failure(minimal), "shrunk": minimal in res.shrunk},
        "boundary": {r.name: res.boundary(r) for r in res.ranges},
        "shrunk": [failure(p) for p in res.shrunk],
        "failures_found": len(res.failures),
        "runs": res.runs,
        "budget": res.budget,
        "stopped": res.stopped,
    }
