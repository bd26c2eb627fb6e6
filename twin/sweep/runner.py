"""Running a sweep: the scenarios cut into batches, the batches sent through an executor, the rows
collected as they come back. Ctrl-C (or SIGTERM/SIGHUP) stops the executor and keeps the rows of
the batches that finished, so the caller can still write them."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from twin.signals import Terminated
from twin.sweep.worker import Job, run_batch

MAX_BATCH = 16  # scenarios per task: long enough to amortize sending it, short enough for steady progress
BATCHES_PER_JOB = 4  # at least this many batches per worker, so the last ones finish together


@dataclass
class SweepRun:
    """What a sweep gave: its rows (by scenario), how many were asked for, the wall time, and the
    exception that stopped it part-way (None when it ran to the end)."""

    rows: list[dict]
    planned: int
    wall_s: float
    stopped_by: BaseException | None = None


def batches(scenarios: Sequence[int], jobs: int, size: int | None = None,
            per_job: int = BATCHES_PER_JOB) -> list[list[int]]:
    """scenarios cut into batches of at most `size` (default: about `per_job` batches per job, at most
    MAX_BATCH), all of nearly one length: a short last batch would leave a worker idle at the end."""
    if size is None:
        size = 1 if jobs == 1 else max(1, min(MAX_BATCH, math.ceil(len(scenarios) / (jobs * per_job))))
    count = math.ceil(len(scenarios) / size)
    n = len(scenarios)
    return [list(scenarios[k * n // count:(k + 1) * n // count]) for k in range(count)]


def run_sweep(job: Job, scenarios: Sequence[int], executor, *, batch_size: int | None = None,
              on_rows: Callable[[list[dict]], None] | None = None) -> SweepRun:
    """Run the scenarios; on_rows is told each finished batch's rows. The caller closes the executor
    (it may run more); an interrupted sweep closes it at once."""
    t0 = time.perf_counter()
    rows: list[dict] = []
    per_job = getattr(executor, "batches_per_job", BATCHES_PER_JOB)
    items = [(job, batch) for batch in batches(scenarios, executor.jobs, batch_size, per_job)]
    stopped_by = None
    try:
        for _, batch_rows in executor.map_unordered(run_batch, items):
            rows.extend(batch_rows)
            if on_rows is not None:
                on_rows(batch_rows)
    except (KeyboardInterrupt, Terminated) as err:
        stopped_by = err
        executor.close()  # stop the workers now; the batches that finished are kept
    rows.sort(key=lambda r: r["scenario"])
    return SweepRun(rows, len(scenarios), time.perf_counter() - t0, stopped_by)
