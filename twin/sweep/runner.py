"""Running a sweep: the scenarios cut into batches (made one at a time, as workers free up), sent
through a `twin.jobs` executor (the sweep's `worker.Job` is the unit of work), each finished
scenario's row kept and told to `on_row` (the journal, the progress) as it comes back. Ctrl-C (or
SIGTERM/SIGHUP) stops the executor and keeps the rows that finished, so the caller can still write
them."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from twin.jobs.guard import Limit
from twin.signals import Terminated
from twin.sweep.spec import SweepSpec
from twin.sweep.worker import Job

# scenarios per task: long enough to amortize sending it, short enough for steady progress
MAX_BATCH = 16
# --scenario-timeout's default: a scenario with no result after this floor plus one wall second per
# simulated second of its task is hung (the twin steps 40-160 times faster than real time, so even
# a recorded failure, run twice, takes a small part of that)
SCENARIO_FLOOR_S = 120.0
WALL_PER_SIM_S = 1.0
BATCHES_PER_JOB = 4  # at least this many batches per worker, so the last ones finish together


@dataclass
class SweepRun:
    """What a sweep gave: its rows (by scenario), how many were asked for, the wall time, and the
    exception that stopped it part-way (None when it ran to the end)."""

    rows: list[dict]
    planned: int
    wall_s: float
    stopped_by: BaseException | None = None


def batch_size(count: int, jobs: int, per_job: int = BATCHES_PER_JOB) -> int:
    """About `per_job` batches per job, at most MAX_BATCH scenarios each (1 with one job)."""
    return 1 if jobs == 1 else max(1, min(MAX_BATCH, math.ceil(count / (jobs * per_job))))


def batches(scenarios: Iterable[int], n: int, size: int) -> Iterator[list[int]]:
    """The n scenarios cut into batches of at most `size`, all of nearly one length (a short last
    batch would leave a worker idle at the end), made as they are asked for: 10M planned cost
    nothing."""
    source = iter(scenarios)
    count = math.ceil(n / size)
    for k in range(count):
        yield list(itertools.islice(source, (k + 1) * n // count - k * n // count))


class ScenarioLimit:
    """The wall seconds a scenario may take when --scenario-timeout is not given: SCENARIO_FLOOR_S
    plus WALL_PER_SIM_S times the task's simulated time, which is the sweep's --timeout when it has
    one, else the longest simulated time of the scenarios finished so far (`seen`). Called by the
    executor each time it needs the limit."""

    def __init__(self, spec: SweepSpec, rows: Iterable[dict] = ()) -> None:
        self.fixed_sim_s = spec.timeout_s
        self.sim_s = 0.0
        for row in rows:
            self.seen(row)

    def seen(self, row: dict) -> None:
        sim_s = row.get("sim_s")
        if isinstance(sim_s, (int, float)) and math.isfinite(sim_s):
            self.sim_s = max(self.sim_s, float(sim_s))

    def __call__(self) -> float:
        sim_s = self.fixed_sim_s if self.fixed_sim_s is not None else self.sim_s
        return SCENARIO_FLOOR_S + WALL_PER_SIM_S * sim_s


def run_sweep(
    job: Job,
    scenarios: Iterable[int],
    executor,
    *,
    count: int | None = None,
    batch_size_n: int | None = None,
    scenario_timeout_s: float | None = None,
    on_row: Callable[[dict], None] | None = None,
    rows: list[dict] | None = None,
    planned: int | None = None,
) -> SweepRun:
    """Run the scenarios (count of them: len(scenarios) when not given); on_row is told each
    finished one. rows: those already finished (a resumed sweep); planned: how many the whole sweep
    has. scenario_timeout_s: wall seconds a scenario may take; None: ScenarioLimit's default, 0: no
    limit. The caller closes the executor (it may run more); an interrupted sweep closes it at
    once."""
    t0 = time.perf_counter()
    rows = list(rows or [])
    limit = ScenarioLimit(job.spec, rows) if scenario_timeout_s is None else None
    timeout: Limit = limit if limit is not None else (scenario_timeout_s or None)
    count = len(scenarios) if count is None else count
    per_job = getattr(executor, "batches_per_job", BATCHES_PER_JOB)
    size = batch_size_n or batch_size(count, executor.jobs, per_job)
    stopped_by = None
    try:
        for _, row in executor.run(job, batches(scenarios, count, size), timeout):
            rows.append(row)
            if limit is not None:
                limit.seen(row)
            if on_row is not None:
                on_row(row)
    except (KeyboardInterrupt, Terminated) as err:
        stopped_by = err
        executor.close()  # stop the workers now; the scenarios that finished are kept
    rows.sort(key=lambda r: r["scenario"])
    return SweepRun(
        rows, count if planned is None else planned, time.perf_counter() - t0, stopped_by
    )
