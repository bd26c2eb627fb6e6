"""pytest integration: the `golden` fixture asserts that a run matches a golden recording.

    def test_pick_place(golden):
        run = record_task(TwinConfig(), "pick_place", {"cycles": 1})
        golden.check(run, "pick_place_one_cycle")   # default: within the run's measured noise floor
        golden.check(run, "pick_place_one_cycle", tolerance="physical", tol=["hold=inf"])

Goldens live in the `twin_goldens_dir` ini folder (default `recordings/`, relative to the rootdir).
A missing golden is written and the test fails (review it, then commit it); `--update-goldens`
rewrites goldens that differ, but never with a run whose task failed (`allow_error=True` says so).
On a mismatch NAME.obtained.mcap and NAME.report.md are left beside the golden, and the failure
message is the diff's text report.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import pytest

from twin.compare.report import render_text, write_report
from twin.compare.result import DiffResult
from twin.compare.tolerances import DEFAULT, Tolerances
from twin.model.recording import Recording


class GoldenChecker:
    """What the `golden` fixture gives a test."""

    def __init__(self, directory: Path, update: bool) -> None:
        self.directory = directory
        self.update = update

    def path(self, name: str) -> Path:
        return self.directory / f"{name}.mcap"

    def check(
        self,
        run: Recording | str | os.PathLike,
        name: str,
        *,
        tolerance: str = DEFAULT,
        tol: Sequence[str] = (),
        event_window_steps: int | None = None,
        event_kinds: frozenset[str] | None = None,
        allow_error: bool = False,
    ) -> DiffResult:
        """Assert that a run matches golden `name`. Under the default `noise` preset the run is
        made once more with its math perturbed (its task re-run, or its commands replayed) to
        measure its noise floor.

        Args:
            run: a Recording (e.g. from `record_task`) or the path of an `.mcap` file.
            name: the golden's name: `NAME.mcap` in the `twin_goldens_dir` folder.
            tolerance: a preset: exact, tight, noise (default), physical or outcome.
            tol: overrides, `CHANNEL.FIELD=VALUE` as `twin diff --tol` takes them.
            event_window_steps: events pair within this many steps (default: the preset's).
            event_kinds: the event kinds to pair one by one (default: all).
            allow_error: a run whose task failed may become or replace the golden.

        Returns:
            The diff (`twin.compare.engine.DiffResult`) when the run matches.

        Raises:
            pytest.fail.Exception: the golden differs (the report is the message; NAME.obtained.mcap
                and NAME.report.md are left beside it), or it did not exist and was written.
        """
        from twin.record.mcap.reader import load
        from twin.verify.check import remade
        from twin.verify.noise import judge
        from twin.verify.replay import save

        candidate = run if isinstance(run, Recording) else load(run)
        tolerances = (
            Tolerances.from_preset(tolerance)
            .with_overrides(list(tol))
            .with_event_window(event_window_steps)
        )
        golden_path = self.path(name)
        obtained = golden_path.with_name(f"{name}.obtained.mcap")
        report = golden_path.with_name(f"{name}.report.md")
        failed = None if allow_error or candidate.outcome == "ok" else _failure(candidate)
        if not golden_path.exists():
            self._write_missing(candidate, golden_path, failed)
        golden = load(golden_path)
        result = judge(golden, candidate, tolerances, remade, event_kinds=event_kinds)
        if result.match:
            for stale in (obtained, report):
                stale.unlink(missing_ok=True)
            return result
        if self.update and failed is None:
            save(candidate, golden_path)
            for stale in (obtained, report):
                stale.unlink(missing_ok=True)
            return result
        save(candidate, obtained)
        write_report(result, report)
        hint = (
            "if the change is intended, rerun with --update-goldens: it rewrites the "
            "golden with this run"
            if failed is None
            else f"this run cannot become the golden: {failed}; pass allow_error=True to "
            "accept a failing run"
        )
        pytest.fail(
            f"run differs from golden {str(golden_path)!r} (obtained: {obtained.name}, report: "
            f"{report.name}; {hint})\n{render_text(result)}",
            pytrace=False,
        )


    @staticmethod
    def _write_missing(candidate: Recording, golden_path: Path, failed: str | None) -> None:
        """A golden that does not exist yet: written from this run and the test failed (review
        it, then commit it); never from a failed run unless asked (allow_error)."""
        from twin.verify.replay import save

        if failed is not None:
            pytest.fail(
                f"golden {str(golden_path)!r} does not exist, and this run cannot "
                f"become it: {failed} "
                "(pass allow_error=True to keep a failing run as the golden)",
                pytrace=False,
            )
        golden_path.parent.mkdir(parents=True, exist_ok=True)
        save(candidate, golden_path)
        pytest.fail(
            f"golden {str(golden_path)!r} did not exist; wrote it from this run: "
            f"review and commit it",
            pytrace=False,
        )

def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("twin", "twin golden recordings")
    group.addoption(
        "--update-goldens",
        action="store_true",
        default=False,
        help="rewrite golden recordings that differ from the run (twin's `golden` fixture)",
    )
    parser.addini(
        "twin_goldens_dir",
        "folder of golden recordings for the `golden` fixture",
        default="recordings",
    )


@pytest.fixture
def golden(request: pytest.FixtureRequest) -> GoldenChecker:
    """Compare runs with golden recordings: golden.check(recording_or_path, "name")."""
    config = request.config
    directory = Path(config.rootpath) / config.getini("twin_goldens_dir")
    return GoldenChecker(directory, bool(config.getoption("--update-goldens")))


def _failure(run: Recording) -> str:
    """Why a run's task did not end ok, in a few words."""
    why = next((e.message for e in run.events if e.kind == "task_error"), "")
    return f"its task ended {run.outcome}" + (f" ({why.splitlines()[0]})" if why else "")
