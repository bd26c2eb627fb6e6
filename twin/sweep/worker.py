"""One scenario's run, in whatever process runs it: the configuration with the scenario's values,
a fresh Twin, the task with its parameters; the row of results; and, for a failing scenario (or
every one, per --save), a recording `failures/scenario-<i>.mcap` that `twin replay` and `twin diff`
read. The MCAP writer runs in this process (a worker must not start a recorder process per
scenario); the file is byte-identical to the one `twin sweep ... --only i` writes.
"""

from __future__ import annotations

import ctypes
import functools
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from twin.model.errors import RecordingError, TwinError, exception_text
from twin.model.sink import Sink
from twin.sim.twin import Twin
from twin.sim.world import engine_versions
from twin.sweep.keys import apply_values, task_values
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import Prepared, SweepSpec, prepare
from twin.tasks import TimeLimit, run_task
from twin.verify.check import task_run

SAVE = ("failures", "all", "none")
COUNTED = ("attach", "release", "break", "suction_empty")
FAILURES, SCENARIOS = "failures", "scenarios"


@dataclass(frozen=True)
class Job:
    """What every batch of one sweep shares: the definition, the output folder (None: write no
    files) and what to record. A `twin.jobs` unit: its items are scenarios, its results rows."""

    spec: SweepSpec
    out_dir: str | None
    save: str = "failures"

    def warm(self) -> None:
        warm(self)

    def run(self, scenario: int) -> dict:
        keep_freed_memory()  # in the process that runs scenarios, once
        return run_scenario(self, scenario)

    def confirm(self, scenario: int) -> dict:
        keep_freed_memory()
        return confirm_scenario(self, scenario)

    def failed(self, scenario: int, reason: str, wall_s: float) -> dict:
        return failed_row(self, scenario, reason, wall_s)


# per worker process: a definition is prepared once
_PREPARED: dict[str, tuple[Prepared, RandomSampler]] = {}


def warm(job: Job) -> None:
    """Prepare the job's definition in this process, so the children forked from it start prepared
    (a Dask worker forks one per task)."""
    _prepared(job.spec)


def _prepared(spec: SweepSpec) -> tuple[Prepared, RandomSampler]:
    key = spec.key()
    if key not in _PREPARED:
        prep = prepare(spec)
        _PREPARED.clear()
        _PREPARED[key] = (prep, RandomSampler(spec.seed, prep.keys))
    return _PREPARED[key]


M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
# free memory at the heap's top kept for reuse: over twice what a scenario frees
TRIM_THRESHOLD_BYTES = 64 << 20
# blocks below this come from the heap (glibc's largest dynamic threshold)
MMAP_THRESHOLD_BYTES = 32 << 20


@functools.cache  # once per process (a forked child inherits the setting with the cache)
def keep_freed_memory() -> None:
    """Have glibc keep the memory a scenario frees for the next one, in whatever process runs
    scenarios (glibc only): each scenario builds and frees a twin, and with glibc's default, dynamic
    trim threshold the heap shrinks and is page-faulted in again by the next, by an amount that
    depends on the process's past, so executors would time unequally. Fixed thresholds make them
    equal (the figures are in CHANGES.md)."""
    if not sys.platform.startswith("linux"):
        return
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)  # absent outside glibc-like C libraries
    if mallopt is not None:
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)


def scenario_path(out_dir: str | os.PathLike, folder: str, scenario: int) -> Path:
    return Path(out_dir) / folder / f"scenario-{scenario}.mcap"


def run_scenario(job: Job, scenario: int) -> dict:
    """Run scenario `scenario` once (twice for a failure that is recorded) and return its row."""
    prep, sampler = _prepared(job.spec)
    values = sampler.values(scenario)
    row = _row(job, scenario, values)
    save_all = job.save == "all" and job.out_dir is not None
    first = scenario_path(job.out_dir, SCENARIOS, scenario) if save_all else None
    t0 = time.perf_counter()
    result = _run(prep, values, scenario, first)
    row.update(result, wall_s=time.perf_counter() - t0)
    if row["outcome"] != "ok" and job.out_dir is not None and job.save != "none":
        failed = scenario_path(job.out_dir, FAILURES, scenario)
        if first is not None:
            try:
                failed.parent.mkdir(exist_ok=True)
                shutil.copyfile(first, failed)
            except OSError as err:
                why = err.strerror or err
                raise RecordingError(f"cannot write {str(failed)!r}: {why}") from err
        else:  # the run is deterministic: running it again, recorded, gives this same run
            _run(prep, values, scenario, failed)
    return row


def confirm_scenario(job: Job, scenario: int) -> dict:
    """Run a scenario whose first run killed its process (or hung) once more, recorded from the
    start as a failure, so that if it dies again its file holds what was flushed before
    (`twin recover` restores it). A run that ends after all is kept per --save like any other."""
    if job.out_dir is None or job.save == "none":
        return run_scenario(job, scenario)
    prep, sampler = _prepared(job.spec)
    values = sampler.values(scenario)
    failed = scenario_path(job.out_dir, FAILURES, scenario)
    t0 = time.perf_counter()
    result = _run(prep, values, scenario, failed)
    row = _row(job, scenario, values)
    row.update(result, wall_s=time.perf_counter() - t0)
    try:
        if job.save == "all":
            scenario_path(job.out_dir, SCENARIOS, scenario).parent.mkdir(exist_ok=True)
            shutil.copyfile(failed, scenario_path(job.out_dir, SCENARIOS, scenario))
        if row["outcome"] == "ok":
            failed.unlink()
    except OSError as err:
        raise RecordingError(
            f"cannot write the recording of scenario {scenario}: {err.strerror or err}"
        ) from err
    return row


def failed_row(job: Job, scenario: int, reason: str, wall_s: float) -> dict:
    """The row of a scenario that gave no result (its process died, or it ran out of wall time)."""
    _, sampler = _prepared(job.spec)
    return {
        **_row(job, scenario, sampler.values(scenario)),
        "outcome": "error",
        "error": reason,
        "placement_error_mm": None,
        **dict.fromkeys(COUNTED, 0),
        "sim_s": None,
        "wall_s": wall_s,
    }


def _row(job: Job, scenario: int, values: dict) -> dict:
    return {
        "scenario": scenario,
        "seed": job.spec.seed,
        **{key.name: value for key, value in values.items()},
    }


class _Tally(Sink):
    """Counts the events a row reports and keeps the worst placement error."""

    def __init__(self) -> None:
        self.counts = dict.fromkeys(COUNTED, 0)
        self.worst_m: float | None = None
        self.sim_s = 0.0

    def on_event(self, event) -> None:
        if event.kind in self.counts:
            self.counts[event.kind] += 1
        elif event.kind == "placed":
            error_m = event.data.get("error_m")
            if isinstance(error_m, (int, float)) and (
                self.worst_m is None or error_m > self.worst_m
            ):
                self.worst_m = float(error_m)


def _run(prep: Prepared, values: dict, scenario: int, mcap_path: Path | None) -> dict:
    """One run; its outcome, error line, counts, worst placement error and simulated time. A task
    that fails raises inside the recorders' block, as in `twin run`, so the file is finalized with
    outcome error and the task's message."""
    spec = prep.spec
    tally, error = _Tally(), ""
    try:
        config = apply_values(prep.config, values, where=f"scenario {scenario}")
        params = {**spec.params, **task_values(values)}
        limit = [TimeLimit(spec.timeout_s)] if spec.timeout_s is not None else []
        if mcap_path is None:
            _task(config, prep.fn, params, tally, limit)
        else:
            from twin.record import open_recorders

            try:
                mcap_path.parent.mkdir(exist_ok=True)
            except OSError as err:
                raise RecordingError(
                    f"cannot create {str(mcap_path.parent)!r}: {err.strerror or err}"
                ) from err
            run = task_run(spec.task, params, mcap_path)
            if spec.timeout_s is not None:
                run["timeout_s"] = spec.timeout_s
            with open_recorders(
                config, run, mcap_path=mcap_path, background=False, engine=engine_versions()
            ) as sinks:
                _task(config, prep.fn, params, tally, [*sinks, *limit])
    except RecordingError:
        # a file that cannot be written ends the sweep (one line), not the scenario
        raise
    except TwinError as err:
        # the task failed, or the scenario's values are invalid: the sweep goes on
        error = exception_text(err) or type(err).__name__
    worst = tally.worst_m
    return {
        "outcome": "error" if error else "ok",
        "error": error.splitlines()[0] if error else "",
        "placement_error_mm": None if worst is None else worst * 1000.0,
        **tally.counts,
        "sim_s": tally.sim_s,
    }


def _task(config, fn, params: dict, tally: _Tally, sinks: list) -> None:
    """Run the task on a fresh twin (tally first among its sinks, which keeps the simulated
    time)."""
    twin = Twin(config, sinks=[tally, *sinks])
    try:
        run_task(twin, fn, params)
    finally:
        tally.sim_s = twin.t_s
        twin.close()
