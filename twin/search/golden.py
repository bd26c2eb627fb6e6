"""A failure found by `twin search`, kept as a regression test: `recordings/search/NAME.toml` (a
one-scenario sweep definition holding the failing values as constants), `NAME.mcap` (its recording,
for `twin replay`) and `NAME.expect.json` (what it is expected to do: fail, and with which reason).

`twin check NAME.toml` runs the scenario again: green while it fails the same way (the same reason,
numbers aside), red when it now passes ("the boundary moved") or fails another way; `--update`
accepts what it does now (the expectation and the recording are rewritten)."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

from twin.model.errors import ConfigError, TwinError
from twin.model.golden_files import expect_path
from twin.model.json_values import load_json_text
from twin.record.outputs import write_atomic
from twin.search.search import run_probe
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import SweepSpec, dump_spec, load_spec, prepare
from twin.sweep.stats import reason
from twin.sweep.worker import _run  # the run a sweep records for a scenario, byte for byte
from twin.verify.check import Outcome

SEARCH_DIR = Path("recordings") / "search"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,99}$")
MAX_BYTES = 1 << 20  # an expectation is a few hundred bytes


def check_name(name: str) -> str:
    """A golden's name: letters, digits, '_' and '-' (it becomes three file names)."""
    if not _NAME.match(name):
        raise ConfigError(
            f"--save-golden {name!r} is invalid; expected a name of letters, digits, '_' or '-' "
            "(at most 100)"
        )
    return name


def record_scenario(spec: SweepSpec, dest: Path) -> None:
    """Record the one-scenario definition's run to dest, whatever its outcome (in this process): the
    file a sweep of that definition writes for its scenario 0."""
    prep = prepare(spec)
    values = RandomSampler(spec.seed, prep.keys).values(0)  # constants: the scenario's values
    _run(prep, values, 0, dest)


def expectation(outcome: str, error: str) -> dict:
    return {"outcome": outcome, "reason": reason(error) if outcome != "ok" else "", "error": error}


def save_golden(
    name: str, spec: SweepSpec, outcome: str, error: str, found: dict, folder: Path = SEARCH_DIR
) -> list[Path]:
    """Write NAME.toml, NAME.mcap and NAME.expect.json into folder (made if missing); `found` is
    what the search reported about it (kept in the expectation, for people)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"cannot make {str(folder)!r}: {err.strerror or err}") from err
    definition, recording = folder / f"{name}.toml", folder / f"{name}.mcap"
    task = spec.task
    if (
        task.endswith(".py") and Path(task).is_file()
    ):  # found relative to the definition, as load_spec does
        task = os.path.relpath(os.path.abspath(task), os.path.abspath(folder))
    write_atomic(definition, dump_spec(SweepSpec(**{**spec.__dict__, "task": task})))
    record_scenario(spec, recording)
    write_atomic(
        expect_path(definition),
        json.dumps({**expectation(outcome, error), "search": found}, indent=2, allow_nan=False)
        + "\n",
    )
    return [definition, recording, expect_path(definition)]


def read_expectation(definition: str) -> dict:
    path = expect_path(definition)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ConfigError(f"search golden {str(path)!r} is larger than {MAX_BYTES} bytes")
        data = load_json_text(path.read_text(), f"search golden {str(path)!r} is not valid JSON")
    except OSError as err:
        raise ConfigError(
            f"search golden {str(path)!r} cannot be read: {err.strerror or err}"
        ) from err
    if (
        not isinstance(data, dict)
        or data.get("outcome") not in ("ok", "error")
        or not isinstance(data.get("reason"), str)
        or not isinstance(data.get("error", ""), str)
    ):
        raise ConfigError(
            f'search golden {str(path)!r} is invalid; expected outcome "ok" or "error" '
            "and a reason text"
        )
    return data


def verdict(expected: dict, outcome: str, error: str) -> tuple[str, str]:
    """("match" or "differ", one line) for a run that gave outcome and error."""
    if expected["outcome"] == "ok":
        if outcome == "ok":
            return "match", "passes, as expected"
        return "differ", f"now fails: {error}; `--update` to accept"
    if outcome == "ok":
        return "differ", "now passes: the boundary moved; `--update` to accept"
    if reason(error) != expected["reason"]:
        return "differ", (
            f"fails differently: expected {expected['reason']!r}, now {error!r}; "
            "`--update` to accept"
        )
    return "match", f"fails the same way: {error}"


def check_search(definition: str, *, update: bool = False, keep: str | None = None) -> Outcome:
    """Run a search golden's scenario again and judge it against its expectation. keep
    (DIR/NAME): one that differs leaves its scenario recorded again and its report there."""
    t0 = time.perf_counter()
    try:
        spec = load_spec(definition)
        if spec.scenarios != 1:
            raise ConfigError(
                f"search golden {definition!r} has scenarios = {spec.scenarios}; expected 1"
            )
        prepare(spec)
        expected = read_expectation(definition)
        outcome, error = run_probe(spec, None)
        status, line = verdict(expected, outcome, error)
        report = (
            f"expected: {expected['outcome']} {expected.get('error', '')!r}\n"
            f"now:      {outcome} {error!r}\n"
        )
        if status == "differ" and update:
            record_scenario(spec, Path(definition).with_suffix(".mcap"))
            kept = {k: v for k, v in expected.items() if k not in ("outcome", "reason", "error")}
            write_atomic(
                expect_path(definition),
                json.dumps({**expectation(outcome, error), **kept}, indent=2, allow_nan=False)
                + "\n",
            )
            return Outcome(
                path=definition,
                status="updated",
                exit_code=0,
                summary=f"rewrote {expect_path(definition).name} and the recording; was: {line}",
                report=report,
                frames=1,
                seconds=time.perf_counter() - t0,
            )
        outcome = Outcome(
            path=definition,
            status=status,
            exit_code=0 if status == "match" else 1,
            summary=line,
            report=report,
            frames=1,
        )
        if status == "differ" and keep is not None:
            outcome.kept = _keep(keep, spec, outcome)
        outcome.seconds = time.perf_counter() - t0
        return outcome
    except TwinError as err:
        return Outcome.of_error(definition, err, time.perf_counter() - t0)


def _keep(base: str, spec: SweepSpec, outcome: Outcome) -> list[str]:
    """--keep for a search golden that differs: DIR/NAME.mcap (the scenario run and recorded once
    more, as --update records it) and DIR/NAME.md (expected and now)."""
    from twin.verify.keep import outcome_markdown, staging

    with staging(base) as staged:
        record_scenario(spec, staged.temp(".mcap"))
        staged.write_text(".md", outcome_markdown(outcome, f"search golden {Path(base).name}"))
        return staged.publish()
