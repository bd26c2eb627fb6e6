"""A sweep in its output folder: the folder made ready, the journal opened (afresh or resumed), the
scenarios run with every finished one journaled, and the results written.

`twin sweep` parses its options and prints; the run itself, and what it leaves in DIR, is here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from twin.model.errors import ConfigError
from twin.sweep.journal import JOURNAL, Journal, same_sweep
from twin.sweep.results import write_definition, write_results
from twin.sweep.runner import SweepRun, run_sweep
from twin.sweep.spec import SweepSpec
from twin.sweep.worker import FAILURES, SCENARIOS, Job


def prepare_folder(path: str, *, clear: bool) -> Path:
    """The output folder, created (its parent must exist, or be runs/); a full sweep removes the
    recordings an earlier sweep left in it (failures/ and scenarios/ scenario-*.mcap), so none is
    mistaken for its own."""
    from twin.record.outputs import make_default_folder

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {path!r} is a file; expected a folder")
    if not make_default_folder(out.parent):  # runs/ is made when missing, as for recordings
        raise ConfigError(f"--out {path!r}: folder {str(out.parent)!r} does not exist")
    try:
        out.mkdir(exist_ok=True)
        if clear:
            for folder in (FAILURES, SCENARIOS):
                for old in (
                    *(out / folder).glob("scenario-*.mcap"),
                    *(out / folder).glob("scenario-*.mcap.partial"),
                ):
                    old.unlink()
    except OSError as err:
        raise ConfigError(f"--out {path!r}: {err.strerror or err}") from err
    return out


def refuse_taken(out_dir: str, spec: SweepSpec, *, only: bool) -> None:
    """ConfigError (exit 2) naming out_dir if it holds anything, unless it is this sweep's own
    folder and only: --only's scenarios go into their own sweep's folder. The same sweep's folder
    continues with --resume; anything else is replaced only with --force."""
    out = Path(out_dir)
    if not out.is_dir() or not any(out.iterdir()):
        return
    if same_sweep(out, spec):
        if only:
            return
        raise ConfigError(
            f"--out {out_dir!r} holds this sweep already; expected --resume to continue it, or "
            "--force to run it afresh"
        )
    raise ConfigError(
        f"--out {out_dir!r} is a folder that is not empty (not this sweep's); expected a new or "
        "empty folder, or --force to write this sweep's files over it"
    )


@dataclass
class Plan:
    """The scenarios a sweep runs in its folder: all of them, the ones a resumed journal lacks, or
    --only's; journal is None for --only (its rows go to no results)."""

    out: Path
    scenarios: Iterable[int]
    count: int
    journal: Journal | None = None

    @property
    def resumed(self) -> int:
        """How many scenarios the journal already had."""
        return len(self.journal.rows) if self.journal is not None else 0


def plan(
    spec: SweepSpec, out_dir: str, *, only: list[int] | None, resume: bool, force: bool = True
) -> Plan:
    """The folder made ready and what runs in it: --only's scenarios (the folder's results left
    alone), or the whole sweep with its journal started afresh or, with resume, continued. Without
    force, a folder that holds anything is refused (refuse_taken) before it is touched."""
    if only is not None and resume:
        raise ConfigError("--only and --resume cannot go together; expected one of them")
    if only is not None and max(only) >= spec.scenarios:
        raise ConfigError(
            f"--only {max(only)} is out of range; the sweep has scenarios 0..{spec.scenarios - 1}"
        )
    if not force and not resume:
        refuse_taken(out_dir, spec, only=only is not None)
    out = prepare_folder(out_dir, clear=only is None and not resume)
    if only is not None:
        return Plan(out, only, len(only))
    if resume and not (out / JOURNAL).exists():
        raise ConfigError(
            f"--resume: {str(out / JOURNAL)!r} does not exist; expected the folder of a sweep "
            "that was stopped (or run without --resume)"
        )
    journal = Journal(out, spec, resume=resume)
    write_definition(out, spec)
    scenarios = (i for i in range(spec.scenarios) if not journal.done(i))
    return Plan(out, scenarios, spec.scenarios - len(journal.rows), journal)


def run(
    spec: SweepSpec,
    the_plan: Plan,
    executor,
    *,
    save: str,
    batch_size_n: int | None,
    scenario_timeout_s: float | None,
    on_row: Callable[[dict], None],
) -> SweepRun:
    """Run the plan's scenarios on the executor, each finished one journaled before on_row hears
    of it; the journal is closed however the run ends (the executor is the caller's)."""
    journal = the_plan.journal

    def journaled(row: dict) -> None:
        if journal is not None:
            journal.add(row)
        on_row(row)

    try:
        return run_sweep(
            Job(spec, str(the_plan.out), save),
            the_plan.scenarios,
            executor,
            count=the_plan.count,
            batch_size_n=batch_size_n,
            scenario_timeout_s=scenario_timeout_s,
            on_row=journaled,
            rows=journal.rows if journal else None,
            planned=spec.scenarios if journal else None,
        )
    finally:
        if journal is not None:
            journal.close()


def finish(spec: SweepSpec, the_plan: Plan, done: SweepRun) -> dict | None:
    """A whole sweep's results.parquet and summary.json written from its rows (its summary); None
    for --only's."""
    if the_plan.journal is None:
        return None
    return write_results(the_plan.out, spec, done.rows, planned=done.planned)
