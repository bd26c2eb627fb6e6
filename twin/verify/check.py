"""Golden-recording checks: re-run each golden from the current code and diff it against the file.

A golden with a task (run.source == "task") is re-run by resolving its task on the configuration
in its metadata; one without (teleop, remote) has its commands replayed. With more than one job
the goldens are a `Checks` unit that `twin.jobs` spreads over guarded processes (or Dask); `update`
rewrites the ones that differ.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from twin.compare.report import headline, render_text
from twin.compare.tolerances import Tolerances
from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, TwinError
from twin.model.recording import Recording
from twin.record.outputs import publish
from twin.sim.twin import Sink, Twin
from twin.sim.world import engine_versions
from twin.tasks import TimeLimit, resolve, run_task, source_sha256
from twin.verify.collectors import ColumnCollector
from twin.verify.noise import judge
from twin.verify.replay import collected, replay, replayed_event_kinds

DEFAULT_DIR = "recordings"
# a golden whose check killed its process (twice): a failed check, not bad input
WORKER_DIED_EXIT = 1


def record_task(
    config: TwinConfig,
    task: str,
    params: dict,
    *,
    sinks: Sequence[Sink] = (),
    task_dir: str | os.PathLike | None = None,
    timeout_s: float | None = None,
) -> Recording:
    """Run a task on a fresh twin and return the run in memory (a failing task is recorded, not
    raised); timeout_s bounds it in simulated time, as `twin run --timeout` did."""
    fn = resolve(_task_path(task, task_dir))
    collector = ColumnCollector()
    limit = [TimeLimit(timeout_s)] if timeout_s is not None else []
    twin = Twin(config, sinks=[collector, *sinks, *limit])
    try:
        # recorded, not raised: the task_error event is part of the run
        with contextlib.suppress(TwinError):
            run_task(twin, fn, dict(params))
    finally:
        twin.close()
    return collected(collector, config, {"source": "task", "task": task, "params": dict(params)})


def task_run(task: str, params: dict, recording: str | os.PathLike | None) -> dict:
    """The run description a recording of `task` stores: a built-in task by name; a task file by its
    path relative to the recording's folder (resolved from there by `twin check`, from any working
    directory or clone) and the sha256 of its source."""
    run = {"source": "task", "task": task, "params": dict(params)}
    if task.endswith(".py") and Path(task).is_file():
        if recording is not None:
            folder = Path(os.path.abspath(recording)).parent
            run["task"] = Path(os.path.relpath(os.path.abspath(task), folder)).as_posix()
        run["task_sha256"] = source_sha256(task)
    return run


def _task_path(task: str, task_dir: str | os.PathLike | None) -> str:
    """A task file as a recording names it: relative to the recording's folder (task_dir); a file
    recorded before paths were stored that way, relative to the working directory."""
    if task.endswith(".py") and task_dir is not None and not Path(task).is_absolute():
        beside = Path(task_dir) / task
        if beside.is_file():
            return str(beside)
    return task


def rerun(
    golden: Recording, *, sinks: Sequence[Sink] = ()
) -> tuple[Recording, frozenset[str] | None]:
    """Re-run golden from the current code: its task if it has one, else its commands.

    Returns the new run and the event kinds to compare (None: all).
    """
    run = golden.run or {}
    if run.get("source") == "task" and run.get("task"):
        task_dir = Path(golden.path).parent if golden.path else None
        new = record_task(
            golden.config,
            run["task"],
            run.get("params") or {},
            sinks=sinks,
            task_dir=task_dir,
            timeout_s=run.get("timeout_s"),
        )
        new.run = dict(run)
        return new, None
    return replay(golden, sinks=sinks), replayed_event_kinds(golden)


def remade(rec: Recording) -> Recording:
    """rerun's new run alone (a noise floor run)."""
    return rerun(rec)[0]


@dataclass
class Outcome:
    """What checking one golden gave."""

    path: str
    # "match", "differ", "updated", "refused" (differs; the re-run failed, not written), "error"
    status: str
    exit_code: int
    summary: str  # the first divergence or the error, one line
    report: str  # the full text report ("" on error)
    frames: int = 0
    seconds: float = 0.0
    kept: list[str] = field(default_factory=list)  # the files --keep wrote for it
    onset: str = ""  # "step N (t = T s)" of the first divergence ("" when none)
    section: str = ""  # its HTML report section (twin.report), when asked for and it differs
    recorded_on: str = ""  # the machine the golden was recorded on, in one line

    @staticmethod
    def of_error(path: str, err: TwinError, seconds: float) -> Outcome:
        """A golden whose check stopped on `err` (exit code and one line from it)."""
        return Outcome(
            path=path,
            status="error",
            exit_code=err.exit_code,
            summary=str(err),
            report="",
            seconds=seconds,
        )


def check_one(
    path: str,
    tolerances: Tolerances,
    update: bool = False,
    allow_error: bool = False,
    keep: str | None = None,
    html: bool = False,
) -> Outcome:
    """Load one golden, re-run it, diff; with update, rewrite it when it differs, but never with a
    run whose task failed unless allow_error (a crash is not a new golden). keep (DIR/NAME, from
    verify.keep.plan_keep): a golden that differs or is refused leaves its re-run, report and diff
    view there; one that matches leaves nothing. html: a golden that differs or is refused gets
    its HTML report section (twin.report.section), drawn here where both runs are."""
    from twin.record.mcap.reader import load
    from twin.verify.keep import KEPT, keep_recording, staging

    t0 = time.perf_counter()
    tmp = Path(path).with_name(Path(path).name + ".tmp")
    with staging(keep) as staged:
        try:
            golden = load(path)
            record_to = tmp if update else staged.temp(".mcap") if staged is not None else None
            new, result = _rerun_and_judge(golden, tolerances, record_to)
            outcome = _verdict(path, golden, new, result, update=update, allow_error=allow_error)
            if outcome.status == "updated":
                publish(tmp, path)
            elif staged is not None and outcome.status in KEPT:
                outcome.kept = keep_recording(staged, golden, new, result, record_to)
            _describe(outcome, golden, new, result, html)
            outcome.seconds = time.perf_counter() - t0
            return outcome
        except TwinError as err:
            return Outcome.of_error(path, err, time.perf_counter() - t0)
        finally:
            tmp.unlink(missing_ok=True)  # a match, or an error part-way: the golden stays as it was


def _describe(outcome: Outcome, golden: Recording, new: Recording, result, html: bool) -> None:
    """The report's part of an outcome: the onset, the machine the golden was recorded on, and
    with html the section of a golden that differs or is refused."""
    from twin.record.machine import machine_text
    from twin.report.section import commands_for, golden_section, onset_text

    outcome.onset = onset_text(result)
    outcome.recorded_on = machine_text(golden.machine) if golden.machine else ""
    if html and outcome.status in ("differ", "refused"):
        commands = commands_for(outcome.path, outcome.kept)
        outcome.section = golden_section(golden, new, result, outcome.path, commands)


def _rerun_and_judge(golden: Recording, tolerances: Tolerances, record_to: Path | None):
    """The golden re-run (recorded to record_to when given, as --update writes a golden) and the
    verdict on it."""
    from twin.record import open_recorders

    recorded_sha, sha_now = (golden.run or {}).get("task_sha256"), _task_sha256_now(golden)
    if record_to is not None:
        run = dict(golden.run or {})
        if sha_now not in (None, "missing"):
            # the rewrite holds the task file's source as it is now
            run["task_sha256"] = sha_now
        with open_recorders(
            golden.config,
            run,
            mcap_path=str(record_to),
            rate=golden.rate_steps,
            # the writer in this process: cheaper here than a recorder process of its own
            # (recordings/README.md, Checking), and a Dask worker (daemonic) may start none
            background=False,
            engine=engine_versions(),
        ) as sinks:
            new, kinds = rerun(golden, sinks=sinks)
    else:
        new, kinds = rerun(golden)
    result = judge(golden, new, tolerances, remade, source=golden, event_kinds=kinds)
    if sha_now is not None and sha_now != recorded_sha:
        result.notes.append(
            f"the task file {golden.run.get('task')!r} changed since the golden was recorded "
            f"(sha256 {recorded_sha[:12]}... then, {sha_now[:12]}... now)"
        )
    return new, result


def _verdict(
    path: str, golden: Recording, new: Recording, result, *, update: bool, allow_error: bool
) -> Outcome:
    """The Outcome of a judged re-run (its time is set by the caller)."""
    report = render_text(result)
    frames = len(golden.frames)
    if result.match:
        return Outcome(
            path=path,
            status="match",
            exit_code=0,
            summary=headline(result),
            report=report,
            frames=frames,
        )
    summary = headline(result)
    if update and new.outcome != "ok" and not allow_error:
        why = next((e.message for e in new.events if e.kind == "task_error"), new.outcome)
        return Outcome(
            path=path,
            status="refused",
            exit_code=1,
            summary=f"not rewritten: the re-run's task failed ({why}); the golden is "
            "left as it was (--allow-error writes it anyway)",
            report=report,
            frames=frames,
        )
    if update:
        return Outcome(
            path=path,
            status="updated",
            exit_code=0,
            summary="rewritten; was: " + summary,
            report=report,
            frames=frames,
        )
    return Outcome(
        path=path, status="differ", exit_code=1, summary=summary, report=report, frames=frames
    )


def _task_sha256_now(golden: Recording) -> str | None:
    """The sha256 of the golden's task file as it is now ("missing" if it is gone); None when the
    golden does not name a task file's hash."""
    run = golden.run or {}
    if not run.get("task_sha256") or not golden.path:
        return None
    path = Path(_task_path(run.get("task", ""), Path(golden.path).parent))
    return source_sha256(path) if path.is_file() else "missing"


@dataclass
class Goldens:
    """The goldens one `twin check` takes, by kind, each in the order found, and the folders it
    walked."""

    recordings: list[str] = field(default_factory=list)  # .mcap goldens
    sweeps: list[str] = field(default_factory=list)  # NAME.toml (NAME.summary.json beside it)
    searches: list[str] = field(default_factory=list)  # NAME.toml with NAME.expect.json beside it
    folders: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.recordings) + len(self.sweeps) + len(self.searches)

    def count_line(self) -> str:
        """`checking 15 goldens: 13 recordings, 1 sweep, 1 search` (kinds with none left out)."""
        kinds = [
            (len(self.recordings), "recording", "recordings"),
            (len(self.sweeps), "sweep", "sweeps"),
            (len(self.searches), "search", "searches"),
        ]
        parts = [f"{n} {one if n == 1 else many}" for n, one, many in kinds if n]
        noun = "golden" if len(self) == 1 else "goldens"
        return f"checking {len(self)} {noun}: " + ", ".join(parts)


def find_goldens(paths: Sequence[str]) -> Goldens:
    """The goldens named: a file as it is (a NAME.toml is a search golden when NAME.expect.json is
    beside it, else a sweep definition, which it must be; anything else an .mcap golden), a folder
    for every golden under it (walk_folder). None: recordings/. Each file once however it is named
    (`G`, `./G`, a folder holding it, a link): two checks of one golden would race on its temporary
    file."""
    from twin.model.golden_files import is_search_golden, is_sweep_golden

    if not paths:
        if not Path(DEFAULT_DIR).is_dir():
            raise ConfigError(
                f"no {DEFAULT_DIR}/ directory in {os.getcwd()!r}; pass goldens (.mcap files, "
                f"NAME.toml sweep or search goldens) or folders of them"
            )
        paths = [DEFAULT_DIR]
    out = Goldens()
    for p in paths:
        path = Path(p)
        if path.is_dir():
            found = walk_folder(p)
            if not len(found):
                raise ConfigError(
                    f"folder {p!r} holds no goldens; expected .mcap recordings, sweep goldens "
                    "(NAME.toml with NAME.summary.json) or search goldens (NAME.toml with "
                    "NAME.expect.json) in it or a sub-folder"
                )
            out.recordings += found.recordings
            out.sweeps += found.sweeps
            out.searches += found.searches
            out.folders.append(p)
        elif p.endswith(".toml"):
            if is_search_golden(path):
                out.searches.append(p)
            elif is_sweep_golden(p, named=True):  # else ConfigError: why it is no definition
                out.sweeps.append(p)
        elif path.exists():
            out.recordings.append(p)
        else:
            raise ConfigError(
                f"golden {p!r} does not exist; expected an .mcap file, a NAME.toml sweep or "
                "search golden, or a folder of them"
            )
    out.recordings = _each_file_once(out.recordings)
    out.sweeps, out.searches = _each_file_once(out.sweeps), _each_file_once(out.searches)
    return out


def walk_folder(folder: str) -> Goldens:
    """Every golden under folder, sub-folders included (linked ones once; hidden ones and hidden
    files skipped), sorted: .mcap recordings but `*.obtained.mcap` and the NAME.mcap of a search
    golden; NAME.toml with NAME.expect.json beside it (a search golden); and the other sweep
    definitions (a .toml with task, scenarios and seed; another .toml, such as a robot profile, is
    skipped, unless NAME.summary.json beside it says it is a golden: an error). Leftovers of an
    interrupted write (`.partial`, `.tmp`) are no .mcap or .toml files."""
    from twin.model.golden_files import is_search_golden, is_sweep_golden

    out, seen = Goldens(), set()
    for top, dirs, files in os.walk(folder, onerror=_unreadable, followlinks=True):
        st = os.stat(top)
        if (st.st_dev, st.st_ino) in seen:  # a link back up the tree: walked already
            dirs[:] = []
            continue
        seen.add((st.st_dev, st.st_ino))
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(f for f in files if not f.startswith(".")):
            path = Path(top) / name
            if name.endswith(".toml"):
                if is_search_golden(path):
                    out.searches.append(str(path))
                elif is_sweep_golden(str(path), named=False):
                    out.sweeps.append(str(path))
            elif name.endswith(".mcap") and not name.endswith(".obtained.mcap"):
                beside = path.with_suffix(".toml")
                if not (beside.is_file() and is_search_golden(beside)):
                    out.recordings.append(str(path))
    return out


def _unreadable(err: OSError) -> None:
    raise ConfigError(f"cannot read folder {err.filename!r}: {err.strerror or err}")


def _each_file_once(paths: list[str]) -> list[str]:
    """paths without a second name of a file already listed (same device and inode), in their
    order."""
    seen: set[tuple[int, int]] = set()
    out = []
    for p in paths:
        st = os.stat(p)
        if (st.st_dev, st.st_ino) not in seen:
            seen.add((st.st_dev, st.st_ino))
            out.append(p)
    return out


class Progress:
    """A progress bar on a terminal; one plain line per golden elsewhere (CI logs)."""

    def __init__(self, total: int, stream: TextIO | None = None) -> None:
        self.total, self.done, self.stream = total, 0, stream or sys.stderr
        self.tty = self.stream.isatty()
        self.outcomes: list[Outcome] = []  # as they finished: what an interrupted check prints

    def __call__(self, outcome: Outcome) -> None:
        self.done += 1
        self.outcomes.append(outcome)
        name = Path(outcome.path).name
        if self.tty:
            width = 30
            filled = width * self.done // self.total
            self.stream.write(
                f"\r[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} {name:<40.40}"
            )
            if self.done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(
                f"[{self.done}/{self.total}] {name}: {outcome.status} ({outcome.seconds:.2f} s)\n"
            )
        self.stream.flush()


@dataclass(frozen=True)
class Checks:
    """The goldens of one check as a `twin.jobs` unit: item i checks paths[i] (check_one) and gives
    its Outcome; a golden whose check killed its process twice is an "error" outcome saying how."""

    paths: tuple[str, ...]
    tolerances: Tolerances
    update: bool = False
    allow_error: bool = False
    keep: tuple[str | None, ...] = ()
    html: bool = False

    def warm(self) -> None:
        from twin.record.mcap.reader import load  # noqa: F401 - imported once, before the fork

    def run(self, item: int) -> Outcome:
        keep = self.keep[item] if self.keep else None
        return check_one(
            self.paths[item],
            self.tolerances,
            update=self.update,
            allow_error=self.allow_error,
            keep=keep,
            html=self.html,
        )

    def confirm(self, item: int) -> Outcome:
        return self.run(item)

    def failed(self, item: int, reason: str, wall_s: float) -> Outcome:
        return Outcome(
            path=self.paths[item],
            status="error",
            exit_code=WORKER_DIED_EXIT,
            summary=reason,
            report="",
            frames=0,
            seconds=wall_s,
        )


def check_all(
    paths: Sequence[str],
    tolerances: Tolerances,
    *,
    update: bool = False,
    jobs: int = 1,
    progress: Callable[[Outcome], None] | None = None,
    allow_error: bool = False,
    executor=None,
    keep: dict[str, str] | None = None,
    html: bool = False,
) -> list[Outcome]:
    """Check every golden: here, one after the other, with jobs == 1 and no executor; else spread
    over `executor` (a `twin.jobs` executor, the caller's to close) or `jobs` guarded local
    processes. Outcomes in the order of paths. keep: DIR/NAME by golden (verify.keep.plan_keep),
    written by the process that checks it. html: each golden that differs carries its HTML report
    section (Outcome.section)."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs {jobs!r} is invalid; expected a whole number >= 1")
    keep = keep or {}
    unit = Checks(
        paths=tuple(paths),
        tolerances=tolerances,
        update=update,
        allow_error=allow_error,
        keep=tuple(keep.get(p) for p in paths),
        html=html,
    )
    results: dict[str, Outcome] = {}
    own = None
    if executor is None and jobs > 1 and len(paths) > 1:
        from twin.jobs.executors import LocalExecutor

        executor = own = LocalExecutor(min(jobs, len(paths)))
    try:
        done = (
            ((i, unit.run(i)) for i in range(len(paths)))
            if executor is None
            else executor.map_unordered(unit, len(paths))
        )
        for i, outcome in done:
            results[paths[i]] = outcome
            if progress:
                progress(outcome)
    finally:
        if own is not None:
            own.close()
    return [results[p] for p in paths]


def check_goldens(
    goldens: Goldens,
    tolerances: Tolerances,
    *,
    executor=None,
    jobs: int = 1,
    update: bool = False,
    allow_error: bool = False,
    keep: dict[str, str] | None = None,
    progress: Callable[[Outcome], None] | None = None,
    check_sweep: Callable[..., Outcome] | None = None,
    check_search: Callable[..., Outcome] | None = None,
    html: bool = False,
) -> list[Outcome]:
    """Every golden of a `twin check`: the recordings (check_all: on the executor, or `jobs` local
    processes), then each statistical golden with check_sweep(definition, update=, keep=), then
    each search golden with check_search(definition, update=, keep=); outcomes in that order. The
    two checkers come from the layers above (sweep, search), which this one does not import."""
    keep = keep or {}
    outcomes = (
        check_all(
            goldens.recordings,
            tolerances,
            update=update,
            jobs=jobs,
            progress=progress,
            allow_error=allow_error,
            executor=executor,
            keep=keep,
            html=html,
        )
        if goldens.recordings
        else []
    )
    later = [(d, check_sweep) for d in goldens.sweeps]
    later += [(d, check_search) for d in goldens.searches]
    for definition, checker in later:
        outcomes.append(checker(definition, update=update, keep=keep.get(definition)))
        if progress:
            progress(outcomes[-1])
    return outcomes


def summary_table(outcomes: list[Outcome]) -> str:
    rows = [("golden", "status", "frames", "time", "detail")] + [
        (o.path, o.status, str(o.frames), f"{o.seconds:.2f} s", o.summary) for o in outcomes
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(r[:4], widths, strict=True)) + "  " + r[4]
        for r in rows
    ]
    counts = {
        s: sum(o.status == s for o in outcomes)
        for s in ("match", "differ", "updated", "refused", "error")
    }
    lines.append(", ".join(f"{n} {s}" for s, n in counts.items() if n) or "nothing checked")
    return "\n".join(lines) + "\n"


def exit_code(outcomes: list[Outcome]) -> int:
    return max((o.exit_code for o in outcomes), default=0)
