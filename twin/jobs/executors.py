"""Where work runs: `LocalExecutor` (this machine's cores) or `DaskExecutor` (Dask's distributed
scheduler: a cluster at --scheduler, or a TLS-secured cluster of its own on 127.0.0.1, cluster.py).
Both offer two calls:
`run_scenarios(job, batches, scenario_timeout_s)`, which runs a sweep's batches (taken from the
iterator only as workers free up) and yields each scenario's row as it finishes, a scenario that
kills its process or hangs becoming a failed row (guard.py); and `map_unordered(fn, items)`, which
runs fn(*item) for each item and yields (index of the item, result) as each finishes
(`twin check` sends goldens through it).
"""

from __future__ import annotations

import itertools
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from twin.model.errors import ConfigError, TwinError
from twin.sweep.guard import GuardedPool, run_batch_guarded
from twin.sweep.worker import failed_row

EXECUTORS = ("local", "dask")
# a local worker that dies (killed, out of memory): its work is sent again, this often
POOL_RESTARTS = 3
# a task that raised is tried again this often; a worker that dies is handled by Dask itself
DASK_RETRIES = 2
# batches in flight per Dask worker: enough to keep it busy, few enough to stay small
DASK_WINDOW_PER_JOB = 4


class WorkerLost(TwinError):
    """The executor lost its workers more often than it retries."""

    exit_code = 1


def _worker_signals() -> None:
    """Pool workers leave Ctrl-C to the parent, which stops them and keeps the results so far, and
    end at once on SIGTERM (the parent's handler, inherited by fork, would unwind them instead)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)


class LocalExecutor:
    """A sweep's scenarios run in `jobs` guarded child processes (guard.GuardedPool). map_unordered
    (goldens): jobs == 1 in this process; else a process pool of `jobs` workers, each importing twin
    once and serving many items, rebuilt when a worker died and the unfinished items sent again (up
    to POOL_RESTARTS times)."""

    name = "local"

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self._pool: ProcessPoolExecutor | None = None
        self._guarded: GuardedPool | None = None

    def run_scenarios(self, job, batches: Iterator[list[int]],
                      scenario_timeout_s: float | None = None) -> Iterator[dict]:
        """A sweep's rows, from `jobs` guarded child processes (also with one job: a scenario that
        kills its process must not take the sweep along)."""
        self._guarded = GuardedPool(job, self.jobs, scenario_timeout_s)
        yield from self._guarded.run(batches)

    def map_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        if self.jobs == 1:
            for i, item in enumerate(items):
                yield i, fn(*item)
            return
        todo = dict(enumerate(items))
        for attempt in itertools.count():
            self._pool = ProcessPoolExecutor(
                max_workers=min(self.jobs, max(1, len(todo))), initializer=_worker_signals
            )
            futures = {self._pool.submit(fn, *item): i for i, item in todo.items()}
            try:
                while futures:
                    done, _ = wait(futures, return_when=FIRST_COMPLETED)
                    for fut in done:
                        i = futures.pop(fut)
                        result = fut.result()
                        del todo[i]
                        yield i, result
                self.close()
                return
            except BrokenProcessPool as err:
                self.close()
                if attempt >= POOL_RESTARTS:
                    raise WorkerLost(
                        f"a local worker process died {attempt + 1} times; "
                        f"{len(todo)} batches not done"
                    ) from err

    def close(self) -> None:
        """Stop the workers now (also part-way: Ctrl-C), dropping queued work."""
        guarded, self._guarded = self._guarded, None
        if guarded is not None:
            guarded.close()
        if self._pool is not None:
            pool, self._pool = self._pool, None
            # queued work is dropped, not finished
            for proc in list(getattr(pool, "_processes", {}).values()):
                if proc.is_alive():
                    proc.terminate()
            pool.shutdown(wait=True, cancel_futures=True)


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

    def __init__(self, jobs: int, scheduler: str | None = None, *, dashboard: bool = False) -> None:
        from twin.sweep.cluster import connect, start_local

        self.jobs, self.scheduler = jobs, scheduler
        self._cluster = self._client = None
        self.dashboard_url: str | None = None
        if scheduler:
            self._client = connect(scheduler)
            self.jobs = max(1, self.worker_count())  # batches sized for the cluster's workers
        else:
            self._cluster, self._client, self.dashboard_url = start_local(jobs, dashboard=dashboard)

    def worker_count(self) -> int:
        return len(self._client.scheduler_info().get("workers", {}))

    def run_scenarios(
        self, job, batches: Iterator[list[int]], scenario_timeout_s: float | None = None
    ) -> Iterator[dict]:
        """A sweep's rows, batch by batch, from at most DASK_WINDOW_PER_JOB batches per worker in
        flight. Each task runs its batch in a guarded child of the Dask worker; a batch whose Dask
        worker was lost anyway (Dask gave up: KilledWorker) is sent again one scenario per task, and
        a scenario that loses its worker alone is a failed row."""
        from distributed import as_completed

        token = os.urandom(6).hex()
        counter = itertools.count()
        pending: dict[str, list[int]] = {}

        def submit(batch: list[int]):
            key = f"twin-{token}-{next(counter)}"
            pending[key] = batch
            return self._client.submit(
                run_batch_guarded,
                job,
                batch,
                scenario_timeout_s,
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
                    if len(batch) > 1:  # find the scenario that loses its worker: one task each
                        for i in batch:
                            done.add(submit([i]))
                        continue
                    why = f"worker died: Dask gave up on it ({type(err).__name__}: {err})"
                    why = why.splitlines()[0]
                    result = [failed_row(job, batch[0], why, 0.0)]
                nxt = next(source, None)
                if nxt is not None:
                    done.add(submit(nxt))
                yield from result
        finally:
            self._cancel(done)

    def _cancel(self, done) -> None:
        futures = list(getattr(done, "futures", ()))
        if futures:
            self._client.cancel(futures)

    def map_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        from distributed import as_completed

        token = os.urandom(6).hex()
        futures = [
            self._client.submit(
                fn, *item, key=f"twin-{token}-{i}", pure=False, retries=DASK_RETRIES
            )
            for i, item in enumerate(items)
        ]
        index = {fut.key: i for i, fut in enumerate(futures)}
        try:
            done = as_completed(
                futures, loop=self._client.loop, with_results=True, raise_errors=False
            )
            for fut, result in done:  # results gathered as they finish, not one round trip each
                if fut.status == "error":
                    err = fut.exception()
                    if isinstance(err, TwinError):
                        raise err
                    # a worker lost too often (KilledWorker), or a crash there
                    raise WorkerLost(f"Dask task {fut.key} failed: {type(err).__name__}: {err}")
                yield index[fut.key], result
        finally:
            for fut in futures:
                if not fut.done():
                    fut.cancel()

    def close(self) -> None:
        client, self._client = getattr(self, "_client", None), None
        if client is not None:
            client.close()
        cluster, self._cluster = self._cluster, None
        if cluster is not None:
            cluster.close()


def make_executor(name: str, jobs: int, scheduler: str | None = None, *, dashboard: bool = False):
    """The executor --executor names; --scheduler and --dashboard only with dask."""
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
        DaskExecutor(jobs, scheduler, dashboard=dashboard)
        if name == "dask"
        else LocalExecutor(jobs)
    )
