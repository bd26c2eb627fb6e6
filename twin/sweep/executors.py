"""Where work runs: `LocalExecutor` (this machine's cores: a process pool whose workers are reused)
or `DaskExecutor` (Dask's distributed scheduler: a cluster at --scheduler, or a LocalCluster on
127.0.0.1 only). Both offer one call, `map_unordered(fn, items)`, which runs fn(*item) for each item
and yields (index of the item, result) as each finishes; the sweep sends batches of scenarios
through it, and `twin check --executor dask` sends goldens.
"""

from __future__ import annotations

import itertools
import logging
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from twin.errors import ConfigError, TwinError

EXECUTORS = ("local", "dask")
POOL_RESTARTS = 3  # a local worker that dies (killed, out of memory): its work is sent again, this often
DASK_RETRIES = 2  # a task that raised is tried again this often; a worker that dies is handled by Dask itself


# A LocalCluster's scheduler, nannies and workers take this configuration. Their event loops' periodic
# work runs beside the simulation (in a worker, a thread that takes the GIL from it; the scheduler on
# the same cores): idle, with Dask's defaults, the scheduler's process took 4.4 % of a core and each
# worker 1.7-1.9 %; with the tick and memory-check intervals below 1.1 % and 0.3-0.4 %, and the
# scheduler's process used 0.06-0.09 s of CPU per 150-scenario sweep instead of 0.14-0.20 s (measured).
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,  # its 10 ms stack sampling takes the GIL from the simulation
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.tick.interval": "500ms",  # an event-loop health check (for warnings), default 20 ms
    "distributed.worker.memory.monitor-interval": "1s",  # spill/pause/terminate checks, default 100 ms
    # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which makes glibc return memory at every
    # free and turns off its adaptive threshold; the simulation allocates all the time (and run_batch
    # keeps freed memory: worker.keep_freed_memory). Threads stay at 1.
    "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
}


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
    """jobs == 1: in this process (no pool); else a process pool of `jobs` workers, each importing
    twin once and serving many items. A pool whose worker died is rebuilt and the unfinished items
    sent again (up to POOL_RESTARTS times)."""

    name = "local"

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self._pool: ProcessPoolExecutor | None = None

    def map_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        if self.jobs == 1:
            for i, item in enumerate(items):
                yield i, fn(*item)
            return
        todo = dict(enumerate(items))
        for attempt in itertools.count():
            self._pool = ProcessPoolExecutor(max_workers=min(self.jobs, max(1, len(todo))), initializer=_worker_signals)
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
                    raise WorkerLost(f"a local worker process died {attempt + 1} times; "
                                     f"{len(todo)} batches not done") from err

    def close(self) -> None:
        """Stop the workers now (also part-way: Ctrl-C), dropping queued work."""
        if self._pool is not None:
            pool, self._pool = self._pool, None
            for proc in list(getattr(pool, "_processes", {}).values()):  # queued work is dropped, not finished
                if proc.is_alive():
                    proc.terminate()
            pool.shutdown(wait=True, cancel_futures=True)


class DaskExecutor:
    """Dask distributed: `Client(scheduler)` for a running cluster (workers there need twin
    installed), else a LocalCluster of `jobs` single-threaded worker processes bound to 127.0.0.1,
    without a dashboard. Items are submitted as tasks and streamed back as they finish; a worker
    that dies has its tasks rescheduled on the others by Dask (the results stay the same: a
    scenario's run depends on its inputs alone)."""

    name = "dask"
    batches_per_job = 2  # a task costs Dask a few round trips: fewer, longer ones (measured: 2 per worker kept
    #                      pace with the local pool where 4 lost 10-25 %)

    def __init__(self, jobs: int, scheduler: str | None = None) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError as err:
            raise ConfigError("--executor dask needs Dask's distributed scheduler; "
                              "install it with pip install 'twin[dask]'") from err
        import dask

        self.jobs, self.scheduler = jobs, scheduler
        self._cluster = None
        dask.config.set(WORKER_CONFIG)  # a LocalCluster's workers take this configuration
        try:
            if scheduler:
                self._client = Client(scheduler, timeout=10, set_as_default=False)
                self.jobs = max(1, self.worker_count())  # batches sized for the cluster's workers
            else:
                self._cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                                             dashboard_address=None, silence_logs=logging.ERROR,
                                             preload=["twin.sweep.worker"])  # twin imported as workers start
                self._client = Client(self._cluster, set_as_default=False)
        except (OSError, TimeoutError, RuntimeError) as err:  # RuntimeError: a worker process could not start
            self.close()
            raise ConfigError(f"cannot start or reach the Dask scheduler {scheduler or 'LocalCluster'!r}: {err} "
                              "(a script that starts one needs the if __name__ == '__main__': guard)") from err

    def worker_count(self) -> int:
        return len(self._client.scheduler_info().get("workers", {}))

    def map_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        from distributed import as_completed

        token = os.urandom(6).hex()
        futures = [self._client.submit(fn, *item, key=f"twin-{token}-{i}", pure=False, retries=DASK_RETRIES)
                   for i, item in enumerate(items)]
        index = {fut.key: i for i, fut in enumerate(futures)}
        try:
            done = as_completed(futures, loop=self._client.loop, with_results=True, raise_errors=False)
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


def make_executor(name: str, jobs: int, scheduler: str | None = None):
    """The executor --executor names; --scheduler only with dask."""
    if name not in EXECUTORS:
        raise ConfigError(f"executor {name!r} is unknown; expected one of {', '.join(EXECUTORS)}")
    if scheduler and name != "dask":
        raise ConfigError("--scheduler needs --executor dask")
    if scheduler and not scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")):
        raise ConfigError(f"--scheduler {scheduler!r} is invalid; expected an address such as tcp://HOST:8786")
    return DaskExecutor(jobs, scheduler) if name == "dask" else LocalExecutor(jobs)
