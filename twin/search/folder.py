"""A search in its output folder: the folder made ready, the search run on an executor, and what it
leaves in DIR (search.json always, also when stopped; the smallest failure's recording and, asked
for, its golden when it ran to the end). `twin search` parses its options and prints; the run is
here."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from twin.model.errors import ConfigError
from twin.search.golden import record_scenario, save_golden
from twin.search.keys import Range
from twin.search.search import Search, SearchResult, probe_spec, result_json
from twin.signals import Terminated
from twin.sweep.runner import ScenarioLimit
from twin.sweep.spec import SweepSpec

RESULT, MINIMAL = "search.json", "minimal.mcap"


@dataclass
class SearchRun:
    """What a search gave: its result, search.json's content, the files written, the wall time,
    and the exception that stopped it part-way (None when it ran to the end)."""

    result: SearchResult
    data: dict
    wrote: list[Path] = field(default_factory=list)
    wall_s: float = 0.0
    stopped_by: BaseException | None = None


def prepare_folder(path: str, *, force: bool = False) -> Path:
    """The output folder, created (its parent must exist, or be runs/); one that holds anything is
    refused unless `force`; an earlier search's minimal.mcap removed, as it is not this one's
    failure."""
    from twin.record.outputs import make_default_folder, refuse_existing

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {path!r} is a file; expected a folder")
    if not force:
        refuse_existing(out, "--out", folder=True)
    if not make_default_folder(out.parent):
        raise ConfigError(f"--out {path!r}: folder {str(out.parent)!r} does not exist")
    try:
        out.mkdir(exist_ok=True)
        (out / MINIMAL).unlink(missing_ok=True)
    except OSError as err:
        raise ConfigError(f"--out {path!r}: {err.strerror or err}") from err
    return out


def run(
    spec: SweepSpec,
    ranges: tuple[Range, ...],
    executor,
    budget: int,
    *,
    out: Path,
    save_as: str | None = None,
    progress: Callable[[str, SearchResult], None] | None = None,
) -> SearchRun:
    """Run the search (each run limited in wall time as a sweep's scenario is: ScenarioLimit) and
    write its files; Ctrl-C or SIGTERM stops it with search.json written, kept in `stopped_by`
    for the caller to raise after printing. The executor is the caller's to close."""
    search = Search(
        spec, ranges, executor, budget, timeout_s=ScenarioLimit(spec), progress=progress
    )
    t0 = time.perf_counter()
    stopped_by = None
    try:
        search.run()
    except (KeyboardInterrupt, Terminated) as err:
        stopped_by = err
    done = SearchRun(search.result, result_json(search.result), stopped_by=stopped_by)
    done.wall_s = time.perf_counter() - t0
    done.wrote = write(done, out, save_as=save_as, record=stopped_by is None)
    return done


def write(done: SearchRun, out: Path, *, save_as: str | None, record: bool) -> list[Path]:
    """search.json, and with record the smallest failure's recording and (save_as) its golden;
    the files written."""
    from twin.record.outputs import write_atomic

    data, result = done.data, done.result
    write_atomic(out / RESULT, json.dumps(data, indent=2, allow_nan=False) + "\n")
    minimal = result.minimal
    wrote = [out / RESULT]
    if record and minimal is not None:
        spec = probe_spec(result.spec, [r.name for r in result.ranges], minimal.values)
        record_scenario(spec, out / MINIMAL)
        wrote.append(out / MINIMAL)
        if save_as:
            wrote += save_golden(
                save_as,
                spec,
                minimal.outcome,
                minimal.error,
                {k: data[k] for k in ("keys", "size", "minimal", "boundary", "runs")},
            )
    return wrote


def refuse_golden(name: str) -> None:
    """--save-golden NAME refused (exit 2) when any of its three files exists, before any work."""
    from twin.model.golden_files import expect_path
    from twin.record.outputs import refuse_existing
    from twin.search.golden import SEARCH_DIR

    definition = SEARCH_DIR / f"{name}.toml"
    for path in (definition, definition.with_suffix(".mcap"), expect_path(definition)):
        refuse_existing(path, f"--save-golden {name}:")
