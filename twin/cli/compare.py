"""The `twin diff`, `twin replay` and `twin check` commands: argument parsing and printing only.

Exit codes: 0 match, 1 mismatch, 2 unreadable or bad input, 3 runs not comparable (diff/replay).
"""

from __future__ import annotations

import argparse
import functools
import os
from pathlib import Path

from twin.cli.args import add_executor_options, whole_number
from twin.cli.record import add_force_option
from twin.cli.ros2 import add_bag_options, diff_with_bag
from twin.compare.tolerances import DEFAULT, FIELDS, PRESETS, Tolerances
from twin.model.errors import ConfigError
from twin.signals import Terminated

# what twin check --force replaces
CHECK_FORCE = "files in the --keep folder and existing --html, --summary, --junit files"

# what a local Dask cluster's workers import as they start: the goldens' and sweeps' code
PRELOAD = ("twin.verify.check", "twin.sweep.worker")

_TOL_HELP = (
    "override one tolerance, CHANNEL.FIELD=VALUE (repeatable; VALUE a number or inf). Fields: "
    + ", ".join(f"{name} [{unit}]" if unit else name for name, (unit, _) in FIELDS.items())
)


def _add_tolerance_options(p: argparse.ArgumentParser, default: str) -> None:
    p.add_argument(
        "--tolerance",
        default=default,
        metavar="PRESET",
        help=f"preset: {', '.join(PRESETS)} (default {default}); see recordings/README.md",
    )
    p.add_argument(
        "--tol", action="append", default=[], metavar="CHANNEL.FIELD=VALUE", help=_TOL_HELP
    )
    p.add_argument(
        "--event-window",
        type=whole_number(0),
        default=None,
        metavar="STEPS",
        help="events match when within this many steps (default: the preset's)",
    )


def _tolerances(args: argparse.Namespace) -> Tolerances:
    tol = Tolerances.from_preset(args.tolerance).with_overrides(args.tol)
    return tol.with_event_window(args.event_window)


def _add_report_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--report",
        action="append",
        default=[],
        metavar="FILE",
        help="also write the report to FILE.md, FILE.json or FILE.xml (JUnit); repeatable",
    )
    p.add_argument(
        "--rrd",
        default=None,
        metavar="FILE.rrd",
        help="write a Rerun recording showing both runs (the candidate as a ghost) and the error",
    )
    p.add_argument(
        "--quiet", "-q", action="store_true", help="print only the verdict and first divergence"
    )
    _add_html_option(p)


def _add_html_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--html",
        default=None,
        metavar="FILE.html",
        help="also write a self-contained HTML report: plots of each diverging field against its "
        "allowance, the paths from above, the events, the pictures at the onset (works offline)",
    )


def _check_outputs(args: argparse.Namespace, inputs: list[str], *, force: bool) -> None:
    """Every output path (--report, --rrd, --html, replay's --record) checked before any work: the
    right suffix, an existing folder, never one of the inputs (also through a link); with
    force=False (diff or replay without --force) none exists yet."""
    from twin.compare.report import report_format
    from twin.record.outputs import check_output

    for path in args.report:
        check_output(path, Path(path).suffix, inputs=inputs, option="--report", force=force)
        report_format(path)
    if args.rrd:
        check_output(args.rrd, ".rrd", inputs=inputs, option="--rrd", force=force)
    if getattr(args, "html", None):
        check_output(args.html, ".html", inputs=inputs, option="--html", force=force)
    if getattr(args, "record", None):
        check_output(args.record, ".mcap", inputs=inputs, option="--record", force=force)


def _emit(result, golden, candidate, args: argparse.Namespace) -> int:
    from twin.compare.report import render_report, render_text
    from twin.record.outputs import write_atomic

    lines = render_text(result).splitlines()
    if args.quiet:
        lines = lines[:1] + [
            line
            for line in lines
            if line.startswith(
                ("first divergence", "  expected", "  the candidate has it", "  the golden has it")
            )
        ]
    print("\n".join(lines))
    for path in args.report:
        write_atomic(path, render_report(result, path))
    if args.rrd:
        from twin.verify.diff_view import write_diff_rrd

        write_diff_rrd(golden, candidate, result, args.rrd)
    if args.html:
        from twin.report.output import write_diff_page

        write_diff_page(args.html, golden, candidate, result, *_again(args))
    return result.exit_code


def _again(args: argparse.Namespace) -> tuple[list[str], str]:
    """The commands that show a diff or replay's difference again, and the report's title."""
    rrd = args.rrd or "diff.rrd"
    if args.command == "diff":
        return [f"twin diff {args.golden} {args.candidate} --rrd {rrd}",
                f"twin view --web {rrd}"], "twin diff"
    record = args.record or "replayed.mcap"
    return [f"twin replay {args.recording} --record {record} --rrd {rrd}",
            f"twin view --web {rrd}"], "twin replay"


def cmd_diff(args: argparse.Namespace) -> int:
    from twin.record.mcap.reader import load
    from twin.verify.check import remade
    from twin.verify.noise import judge

    bag_code = diff_with_bag(args, _tolerances)  # a side is a ROS 2 bag: joint logs compared
    if bag_code is not None:
        return bag_code
    tol = _tolerances(args)
    _check_outputs(args, [args.golden, args.candidate], force=args.force)
    golden, candidate = load(args.golden), load(args.candidate)
    result = judge(golden, candidate, tol, remade, force=args.force)
    return _emit(result, golden, candidate, args)


def cmd_replay(args: argparse.Namespace) -> int:
    from twin.record.mcap.reader import load
    from twin.verify.noise import judge
    from twin.verify.replay import REPLAYED_EVENT_KINDS, replay, replay_run, replayed_event_kinds

    tol = _tolerances(args)
    _check_outputs(args, [args.recording], force=args.force)
    rec = load(args.recording)
    if args.record:
        from twin.record import open_recorders
        from twin.sim.world import engine_versions

        with open_recorders(
            rec.config, replay_run(rec), mcap_path=args.record, engine=engine_versions()
        ) as sinks:
            new = replay(rec, sinks=sinks)
        new.path, new.finalized = args.record, True  # the file was finalized as the block closed
    else:
        new = replay(rec)
    kinds = replayed_event_kinds(rec)
    result = judge(rec, new, tol, replay, source=rec, event_kinds=kinds)
    if kinds is not None:
        result.notes.append(
            "this recording predates recorded task and client events: replay compares only the "
            "events the twin itself emits: " + ", ".join(sorted(REPLAYED_EVENT_KINDS))
        )
    return _emit(result, rec, new, args)


def cmd_check(args: argparse.Namespace) -> int:
    from twin.verify.check import Progress, exit_code, find_goldens, summary_table

    tol = _tolerances(args)
    if args.force and not (args.keep or args.html or args.summary or args.junit):
        raise ConfigError(
            f"--force replaces {CHECK_FORCE}; expected --keep DIR, --html, --summary or --junit too"
        )
    goldens = find_goldens(args.paths)
    _check_outputs_of_check(args, goldens)
    keep = None
    if args.keep:
        from twin.verify.keep import plan_keep

        keep = plan_keep(args.keep, goldens, force=args.force)  # before any work
    print(goldens.count_line(), flush=True)
    progress = Progress(len(goldens))
    try:
        outcomes = _check_goldens(args, goldens, tol, keep, progress)
    except (KeyboardInterrupt, Terminated):  # what finished, then 130 or 128 + the signal
        print(summary_table(progress.outcomes), end="")
        print(f"interrupted: {len(progress.outcomes)} of {len(goldens)} goldens checked")
        raise
    if args.junit:
        from twin.compare.report import render_check_junit
        from twin.record.outputs import write_atomic

        write_atomic(args.junit, render_check_junit(outcomes))
    from twin.report.output import write_check_reports

    written = write_check_reports(outcomes, args.html, args.summary)
    for o in outcomes:
        if o.status in ("differ", "refused") and args.verbose:
            print(f"== {o.path}\n{o.report}")
    print(summary_table(outcomes), end="")
    updated = [o.path for o in outcomes if o.status == "updated"]
    if updated:
        print("rewrote: " + ", ".join(updated))
    kept = [os.path.join(args.keep, Path(f).name) for o in outcomes for f in o.kept]
    if kept:
        print("kept: " + ", ".join(kept))
    if written:
        print("report: " + ", ".join(written))
    return exit_code(outcomes)


def _check_outputs_of_check(args: argparse.Namespace, goldens) -> None:
    """--html, --summary and --junit checked before any work: the right suffix, an existing
    folder, none of the goldens' files, and without --force none exists yet."""
    from twin.record.outputs import check_output

    inputs = goldens.recordings + goldens.sweeps + goldens.searches
    for option, path, suffix in (
        ("--html", args.html, ".html"),
        ("--summary", args.summary, ".md"),
        ("--junit", args.junit, ".xml"),
    ):
        if path:
            check_output(path, suffix, inputs=inputs, option=option, force=args.force)


def _check_goldens(args: argparse.Namespace, goldens, tol: Tolerances, keep, progress) -> list:
    """Every golden checked (verify.check.check_goldens), on the executor --executor and --jobs
    ask for when the work fans out."""
    from twin.jobs.executors import make_executor
    from twin.search.golden import check_search
    from twin.sweep.golden import check_sweep
    from twin.verify.check import check_goldens

    fans_out = args.executor == "dask" or args.jobs > 1 or goldens.sweeps
    executor = (
        make_executor(args.executor, args.jobs, args.scheduler, preload=PRELOAD)
        if fans_out
        else None
    )
    try:
        return check_goldens(
            goldens,
            tol,
            executor=executor if args.executor == "dask" or args.jobs > 1 else None,
            update=args.update,
            allow_error=args.allow_error,
            keep=keep,
            progress=progress,
            check_sweep=functools.partial(check_sweep, executor=executor, html=bool(args.html)),
            html=bool(args.html),
            check_search=check_search,
        )
    finally:
        if executor is not None:
            executor.close()


def add_compare_commands(sub: argparse._SubParsersAction) -> None:
    """Add diff, replay and check to the `twin` command's subparsers."""
    p = sub.add_parser(
        "diff",
        help="compare two recordings by content (exit 0 match, 1 mismatch, 2 bad input, "
        "3 not comparable)",
    )
    p.add_argument("golden", help="the reference recording (.mcap, or a ROS 2 bag)")
    p.add_argument("candidate", help="the recording to check (.mcap, or a ROS 2 bag)")
    _add_tolerance_options(p, DEFAULT)
    add_bag_options(p)
    p.add_argument(
        "--force",
        action="store_true",
        help="compare even when robot profile, time step or scene objects differ; also replace "
        "existing --report, --rrd and --html files (without it an existing one is refused before "
        "any work; the old one stays until the new one is complete)",
    )
    _add_report_options(p)
    p.set_defaults(func=cmd_diff)

    p = sub.add_parser(
        "replay", help="rebuild the twin from a recording, feed its commands back, compare"
    )
    p.add_argument("recording", help="the recording to replay (.mcap)")
    p.add_argument(
        "--record", default=None, metavar="NEW.mcap", help="also record the replayed run"
    )
    add_force_option(p, "the --record, --rrd, --report or --html file")
    _add_tolerance_options(p, DEFAULT)
    _add_report_options(p)
    p.set_defaults(func=cmd_replay)

    _add_check_command(sub)


def _add_check_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="re-run every golden and compare (default: every golden under recordings/): "
        "recordings field by field, sweep goldens by statistics, search goldens by outcome",
    )
    p.add_argument(
        "paths",
        nargs="*",
        help="golden .mcap files, sweep goldens (NAME.toml with NAME.summary.json beside it), "
        "search goldens (NAME.toml with NAME.expect.json), or folders: every golden under a "
        "folder, sub-folders included (default: recordings/)",
    )
    p.add_argument(
        "--update",
        action="store_true",
        help="rewrite the goldens that differ (and say which); never with a run whose task failed",
    )
    p.add_argument(
        "--allow-error",
        action="store_true",
        help="with --update: also write a run whose task failed (its outcome stays error)",
    )
    p.add_argument(
        "--keep",
        default=None,
        metavar="DIR",
        help="for each golden that differs (or is refused), keep in DIR what shows why: an .mcap "
        "golden's re-run DIR/NAME.mcap (the file --update would write), its report DIR/NAME.md "
        "and diff view DIR/NAME.rrd; a sweep's report and new DIR/NAME.summary.json (and "
        "NAME.results.parquet); a search golden's re-run and report. Nothing for a golden that "
        "matches. NAME: the golden's stem (a__x, b__x for a/x.mcap and b/x.mcap). DIR is made if "
        "missing, and may not lie in a folder being checked",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help=f"replace {CHECK_FORCE} (without it, a file --keep would write or an existing "
        "report file is refused before any work; the old one stays until the new one is "
        "complete)",
    )
    add_executor_options(p)
    p.add_argument(
        "--verbose",
        "-v",
        action="store_true",
        help="print the full report of each differing golden",
    )
    p.add_argument(
        "--junit",
        default=None,
        metavar="FILE.xml",
        help="also write a JUnit report, one case per golden",
    )
    _add_html_option(p)
    p.add_argument(
        "--summary",
        default=None,
        metavar="FILE.md",
        help="also write the job summary in Markdown (the table and what changed, no pictures); "
        "with $GITHUB_STEP_SUMMARY set, it is appended there without being asked",
    )
    _add_tolerance_options(p, DEFAULT)
    p.set_defaults(func=cmd_check, interrupt=True)  # Ctrl-C even as a background job
