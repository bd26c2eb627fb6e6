"""Running a sweep: the scenarios cut into batches (made one at a time, as workers free up), sent
through an executor, each finished scenario's row kept and told to `on_row` (the journal, the
progress) as it comes back. Ctrl-C (or SIGTERM/SIGHUP) stops the executor and keeps the rows that
finished, so the caller can still write them."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from twin.signals import Terminated
from twin.sweep.worker import Job

# scenarios per task: long enough to amortize sending it, short enough for steady progress
MAX_BATCH = 16
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
    has. The caller closes the executor (it may run more); an interrupted sweep closes it at
    once."""
    t0 = time.perf_counter()
    rows = list(rows or [])
    count = len(scenarios) if count is None else count
    per_job = getattr(executor, "batches_per_job", BATCHES_PER_JOB)
    size = batch_size_n or batch_size(count, executor.jobs, per_job)
    stopped_by = None
    try:
        for _, row in executor.run(job, batches(scenarios, count, size), scenario_timeout_s):
            rows.append(row)
            if on_row is not None:
                on_row(row)
    except (KeyboardInterrupt, Terminated) as err:
        stopped_by = err
        executor.close()  # stop the workers now; the scenarios that finished are kept
    rows.sort(key=lambda r: r["scenario"])
    return SweepRun(
        rows, count if planned is None else planned, time.perf_counter() - t0, stopped_by
    )
