"""Where work runs: `LocalExecutor` (this machine's cores) or `DaskExecutor` (Dask's distributed
scheduler: a cluster at --scheduler, or a TLS-secured cluster of its own on 127.0.0.1, cluster.py).
Both run a `unit.Unit` with two calls: `run(unit, batches, timeout_s)`, which runs the batches of
items (taken from the iterator only as workers free up) and yields (item, result) as each finishes,
an item that kills its process or hangs past timeout_s becoming the unit's failed result (guard.py;
timeout_s may be a callable, asked as the work goes: a limit that follows the results); and
`map_unordered(unit, count, timeout_s)`, the same for items 0..count-1 one at a time (the goldens
of `twin check`, a search round's points).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

from twin.jobs.guard import GuardedPool, Limit, limit_now, run_batch_guarded
from twin.jobs.unit import Unit
from twin.model.errors import ConfigError, TwinError

EXECUTORS = ("local", "dask")
# a task that raised is tried again this often; a worker that dies is handled by Dask itself
DASK_RETRIES = 2
# batches in flight per Dask worker: enough to keep it busy, few enough to stay small
DASK_WINDOW_PER_JOB = 4


class LocalExecutor:
    """A unit's items run in `jobs` guarded child processes (guard.GuardedPool), also with one job:
    an item that kills its process must not take the command along."""

    name = "local"

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self._guarded: GuardedPool | None = None

    def run(
        self, unit: Unit, batches: Iterable[list[int]], timeout_s: Limit = None
    ) -> Iterator[tuple[int, Any]]:
        self._guarded = GuardedPool(unit, self.jobs, timeout_s)
        yield from self._guarded.run(batches)

    def map_unordered(
        self, unit: Unit, count: int, timeout_s: Limit = None
    ) -> Iterator[tuple[int, Any]]:
        return self.run(unit, ([i] for i in range(count)), timeout_s)

    def close(self) -> None:
        """Stop the workers now (also part-way: Ctrl-C), dropping queued work."""
        guarded, self._guarded = self._guarded, None
        if guarded is not None:
            guarded.close()


class DaskExecutor:
    """Dask distributed: `cluster.connect(scheduler)` for a running cluster (workers there need twin
    installed), else `cluster.start_local`: `jobs` single-threaded worker processes on 127.0.0.1
    that speak TLS with a certificate made for the run, and no HTTP server unless `dashboard`.
    Batches are submitted as tasks from a bounded window and streamed back as they finish; a worker
    that dies has its tasks rescheduled on the others by Dask (the results stay the same: a
    scenario's run depends on its inputs alone)."""

    name = "dask"
    # a task costs Dask a few round trips: fewer, longer ones (measured: 2 per worker kept
    batches_per_job = 2
    #                      pace with the local pool where 4 lost 10-25 %)

    def __init__(
        self,
        jobs: int,
        scheduler: str | None = None,
        *,
        dashboard: bool = False,
        preload: Sequence[str] = (),
    ) -> None:
        from twin.jobs.cluster import connect, start_local

        self.jobs, self.scheduler = jobs, scheduler
        self._cluster = self._client = None
        self.dashboard_url: str | None = None
        if scheduler:
            self._client = connect(scheduler)
            self.jobs = max(1, self.worker_count())  # batches sized for the cluster's workers
        else:
            self._cluster, self._client, self.dashboard_url = start_local(
                jobs, dashboard=dashboard, preload=preload
            )

    def worker_count(self) -> int:
        return len(self._client.scheduler_info().get("workers", {}))

    def run(
        self, unit: Unit, batches: Iterable[list[int]], timeout_s: Limit = None
    ) -> Iterator[tuple[int, Any]]:
        """(item, result) pairs, batch by batch, from at most DASK_WINDOW_PER_JOB batches per worker
        in flight. Each task runs its batch in a guarded child of the Dask worker; a batch whose
        Dask worker was lost anyway (Dask gave up: KilledWorker) is sent again one item per task,
        and an item that loses its worker alone is a failed one."""
        from distributed import as_completed

        token = os.urandom(6).hex()
        counter = itertools.count()
        pending: dict[str, list[int]] = {}

        def submit(batch: list[int]):
            key = f"twin-{token}-{next(counter)}"
            pending[key] = batch
            return self._client.submit(
                run_batch_guarded,
                unit,
                batch,
                limit_now(timeout_s),  # the limit as the batch leaves
                key=key,
                pure=False,
                retries=DASK_RETRIES,
            )

        window = max(1, self.jobs * DASK_WINDOW_PER_JOB)
        source = iter(batches)
        done = as_completed([], loop=self._client.loop, with_results=True, raise_errors=False)
        for batch in itertools.islice(source, window):
            done.add(submit(batch))
        try:
            for fut, result in done:
                batch = pending.pop(fut.key)
                if fut.status == "error":
                    err = fut.exception()
                    if isinstance(err, TwinError):
                        raise err
                    if len(batch) > 1:  # find the item that loses its worker: one task each
                        for i in batch:
                            done.add(submit([i]))
                        continue
                    why = f"worker died: Dask gave up on it ({type(err).__name__}: {err})"
                    result = [(batch[0], unit.failed(batch[0], why.splitlines()[0], 0.0))]
                nxt = next(source, None)
                if nxt is not None:
                    done.add(submit(nxt))
                yield from result
        finally:
            self._cancel(done)

    def map_unordered(
        self, unit: Unit, count: int, timeout_s: Limit = None
    ) -> Iterator[tuple[int, Any]]:
        return self.run(unit, ([i] for i in range(count)), timeout_s)

    def _cancel(self, done) -> None:
        futures = list(getattr(done, "futures", ()))
        if futures:
            self._client.cancel(futures)

    def close(self) -> None:
        client, self._client = getattr(self, "_client", None), None
        if client is not None:
            client.close()
        cluster, self._cluster = self._cluster, None
        if cluster is not None:
            cluster.close()


def make_executor(
    name: str,
    jobs: int,
    scheduler: str | None = None,
    *,
    dashboard: bool = False,
    preload: Sequence[str] = (),
):
    """The executor --executor names; --scheduler and --dashboard only with dask. preload: modules
    a local Dask cluster's workers import as they start (the work's own, so its first task is not
    slower)."""
    if name not in EXECUTORS:
        raise ConfigError(f"executor {name!r} is unknown; expected one of {', '.join(EXECUTORS)}")
    if scheduler and name != "dask":
        raise ConfigError("--scheduler needs --executor dask")
    if dashboard and (name != "dask" or scheduler):
        raise ConfigError(
            "--dashboard needs --executor dask without --scheduler (a cluster of your "
            "own has its own)"
        )
    if scheduler and not scheduler.startswith(("tcp://", "tls://")):
        raise ConfigError(
            f"--scheduler {scheduler!r} is invalid; expected an address such as tcp://HOST:8786 "
            "or tls://HOST:8786"
        )
    return (
        DaskExecutor(jobs, scheduler, dashboard=dashboard, preload=preload)
        if name == "dask"
        else LocalExecutor(jobs)
    )
