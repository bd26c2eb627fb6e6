"""Benchmark section: scenario sweeps.

The shipped sweep golden's definition (recordings/sweeps/pick_place_jitter.toml: pick_place, one
cycle, the box jittered, two masses; 150 scenarios), recording nothing (--save none):
scenarios per second on 1 and 2 local workers (the pool's start included), on a warm Dask
LocalCluster of 2 workers (its start reported apart: a cluster is started once; a new one for each
pair, closed before the local pool of the pair runs), and what the sweep adds per scenario (CPU
time, on its first 48 scenarios) over building the twin and running the task alone in a loop.

Every process that runs scenarios keeps the memory they free (worker.keep_freed_memory), so a
scenario's cost does not depend on the process's past. The sweep runs its scenarios in forked
children, with one worker too; the loop without a sweep, and the sweep it is compared with, run in
a forked child of this process, so the allocator setting does not stay here for the sections after.
tools/bench.py calls bench(ctx); `python tools/bench_sweep.py` runs it alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path

from twin.jobs.executors import DaskExecutor, LocalExecutor
from twin.model.errors import TwinError
from twin.sim.twin import Twin
from twin.sweep.keys import apply_values, task_values
from twin.sweep.runner import run_sweep
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import load_spec, prepare
from twin.sweep.worker import Job, keep_freed_memory
from twin.tasks import run_task

ROOT = Path(__file__).resolve().parents[1]
DEFINITION = ROOT / "recordings" / "sweeps" / "pick_place_jitter.toml"
# the whole golden: a sweep's fixed costs (pool or task start, the last batches) amortized as in use
SCENARIOS = 150
OVERHEAD_SCENARIOS = 48


def _spec(scenarios: int = SCENARIOS):
    return dataclasses.replace(load_spec(DEFINITION), scenarios=scenarios)


def _sweep_rate(executor) -> float:
    """Scenarios per wall second of one sweep through executor (left open)."""
    spec = _spec()
    done = run_sweep(Job(spec, None, "none"), range(spec.scenarios), executor)
    assert len(done.rows) == spec.scenarios
    return spec.scenarios / done.wall_s


def _dask_rate(rates: list[float]) -> float:
    """A new Dask LocalCluster of 2 workers: its rate on the sweep appended to rates, once warm (a
    sweep of 8 scenarios first, untimed: the definition prepared in both workers), and its start
    time returned. It is closed before the local pool runs: idle, its scheduler (in this process)
    and its two workers took 4 % and 2 % and 2 % of a core (measured over 15 s), which the pool
    running beside it paid and Dask's own run did not."""
    t0 = time.perf_counter()
    cluster = DaskExecutor(2, preload=("twin.sweep.worker",))
    start_s = time.perf_counter() - t0
    try:
        run_sweep(Job(_spec(8), None, "none"), range(8), cluster)
        rates.append(_sweep_rate(cluster))
    finally:
        cluster.close()
    return start_s


def _in_child(fn) -> float:
    """fn() run in a forked child of this process; its result."""
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=lambda: send.send(fn()))
    child.start()
    send.close()
    try:
        return receive.recv()
    finally:
        child.join()


def _local_rate(jobs: int) -> float:
    executor = LocalExecutor(jobs)
    try:
        return _sweep_rate(executor)
    finally:
        executor.close()


def _bare_cpu_s(scenarios: int = OVERHEAD_SCENARIOS) -> float:
    """CPU seconds per scenario of the same runs with no sweep around them: a Twin per scenario and
    the task, the freed memory kept as a sweep's workers keep it (call in a child)."""
    keep_freed_memory()
    spec = _spec(scenarios)
    prep = prepare(spec)
    sampler = RandomSampler(spec.seed, prep.keys)
    t0 = time.process_time()
    for i in range(spec.scenarios):
        values = sampler.values(i)
        twin = Twin(apply_values(prep.config, values))
        # a failing scenario is part of the work, as in the sweep
        with contextlib.suppress(TwinError):
            run_task(twin, prep.fn, {**spec.params, **task_values(values)})
        twin.close()
    return (time.process_time() - t0) / spec.scenarios


def _sweep_cpu_s() -> float:
    """CPU seconds per scenario of a 1-worker sweep of the same scenarios: this process's and its
    worker's (a child, counted once it has ended)."""
    spec = _spec(OVERHEAD_SCENARIOS)
    t0 = _cpu_s()
    executor = LocalExecutor(1)
    run_sweep(Job(spec, None, "none"), range(spec.scenarios), executor)
    executor.close()
    return (_cpu_s() - t0) / spec.scenarios


def _cpu_s() -> float:
    """CPU seconds of this process and its ended children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _overhead_ms() -> float:
    """Milliseconds of CPU per scenario a 1-worker sweep adds to the runs alone (call in a child).
    A few runs first, not counted: a child's first runs grow its heap and cost it 0.5-1 ms more
    per scenario (measured), which would be charged to whichever loop went first."""
    _bare_cpu_s(8)
    bare_s = _bare_cpu_s()
    return (_sweep_cpu_s() - bare_s) * 1000.0


def bench(ctx) -> list[tuple[str, str]]:
    """Each repeat measures its pair back to back (1 then 2 local workers; a new Dask cluster
    against the mean of the 2-worker pool's runs just before and just after it) and the figures are
    medians of the pairs' ratios: a busy moment of the shared machine then spoils one pair, not the
    comparison, and a load that rises or falls through a pair is seen by both sides alike."""
    repeats = ctx.repeats
    one, two, speedups, overheads = [], [], [], []
    for _ in range(repeats):
        one.append(_local_rate(1))
        two.append(_local_rate(2))
        speedups.append(two[-1] / one[-1])
        overheads.append(_in_child(_overhead_ms))
    starts, dask, local, vs_local = [], [], [_local_rate(2)], []
    # each Dask run between two of the local pool: the load's drift cancels
    for _ in range(repeats):
        starts.append(_dask_rate(dask))
        local.append(_local_rate(2))
        vs_local.append(dask[-1] / statistics.mean(local[-2:]))
    start_s = statistics.median(starts)
    one, two, dask = statistics.median(one), statistics.median(two), statistics.median(dask)
    pairs = vs_local
    speedup, vs_local, overhead_ms = (
        statistics.median(speedups),
        statistics.median(vs_local),
        statistics.median(overheads),
    )
    ctx.figures.update(
        sweep_scenarios_per_s=two,
        sweep_speedup_jobs2=speedup,
        sweep_dask_vs_local=vs_local,
        sweep_overhead_ms_per_scenario=overhead_ms,
        sweep_scenarios_per_s_jobs1=one,
        sweep_dask_scenarios_per_s=dask,
        sweep_dask_start_s=start_s,
    )
    what = f"{SCENARIOS} scenarios of {DEFINITION.name}, --save none"
    return [
        (f"{what}: scenarios/s, 1 local worker (median of {repeats})", f"{one:.1f}"),
        ("scenarios/s, 2 local workers (pool start included)", f"{two:.1f}"),
        (
            "2 workers over 1 (median of the pairs' ratios; goal >= 1.6)",
            f"{speedup:.2f}x (pairs {min(speedups):.2f}..{max(speedups):.2f})",
        ),
        (
            (
                "scenarios/s, Dask LocalCluster of 2 workers (started, warm) / 2 local "
                "workers around it"
            ),
            f"{dask:.1f} / {statistics.median(local):.1f}",
        ),
        (
            "Dask over 2 local workers (median of the ratios to the runs around it; goal >= 0.9)",
            f"{vs_local:.2f}x (pairs {min(pairs):.2f}..{max(pairs):.2f})",
        ),
        ("Dask LocalCluster start (2 workers, twin preloaded; median)", f"{start_s:.2f} s"),
        (
            "sweep overhead per scenario: CPU time of a 1-worker sweep over the runs alone",
            f"{overhead_ms:.2f} ms",
        ),
    ]


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench import run

    sys.exit(run(["sweep"], repeats=3))
