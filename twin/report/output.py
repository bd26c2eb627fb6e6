"""Writing the report and the job summary: the page and --summary FILE.md replace their file
whole (written aside, then renamed), the step summary GitHub names in $GITHUB_STEP_SUMMARY is
appended to, as GitHub asks."""

from __future__ import annotations

import os

from twin.model.errors import OutputError
from twin.record.outputs import write_atomic

STEP_SUMMARY = "GITHUB_STEP_SUMMARY"


def write_page(path: str | os.PathLike, text: str) -> None:
    write_atomic(path, text)


def step_summary_path() -> str | None:
    """The file $GITHUB_STEP_SUMMARY names (None when unset or empty)."""
    return os.environ.get(STEP_SUMMARY) or None


def append_step_summary(path: str, text: str) -> None:
    """Add text to the step's summary file (OutputError naming it when it cannot be)."""
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write(text + "\n")
    except OSError as err:
        raise OutputError(
            f"cannot append the job summary to ${STEP_SUMMARY} {path!r}: {err.strerror or err}"
        ) from err


def write_diff_page(path: str, golden, candidate, result, commands: list[str], title: str) -> None:
    """--html of twin diff and twin replay: the page of one compared pair."""
    from twin.record.machine import machine, machine_text
    from twin.report.page import render_page
    from twin.report.section import diff_entry

    name = golden.path or "golden"
    entry = diff_entry(golden, candidate, result, name, commands)
    write_page(path, render_page([entry], title, machine_text(machine())))


def write_check_reports(outcomes: list, html: str | None, summary: str | None) -> list[str]:
    """twin check's --html page and --summary file, and the step summary when GitHub names one;
    the paths written."""
    from twin.record.machine import machine, machine_text
    from twin.report.page import entry_of, render_page, render_summary

    entries = [entry_of(o) for o in outcomes]
    written = []
    if html:
        write_page(html, render_page(entries, "twin check", machine_text(machine())))
        written.append(html)
    markdown = render_summary(entries, "twin check")
    if summary:
        write_atomic(summary, markdown)
        written.append(summary)
    step = step_summary_path()
    if step:
        append_step_summary(step, markdown)
        written.append(f"${STEP_SUMMARY}")
    return written
