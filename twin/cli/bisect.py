"""The `twin bisect` command: argument parsing and printing only.

Exit codes: 0 the first bad commit found, 1 good and bad do not differ, 2 bad input, 3 skipped
commits leave it undecided.
"""

from __future__ import annotations

import argparse
import json

from twin.cli.compare import _add_tolerance_options, _tolerances
from twin.cli.record import add_force_option
from twin.compare.tolerances import DEFAULT
from twin.record.outputs import check_output, write_atomic


def _short(tried) -> str:
    return f"{tried.commit[:12]} {tried.subject}"


def _print_tried(tried) -> None:
    where = " (cached)" if tried.cached else ""
    line = f"  {tried.verdict:<4}  {_short(tried)}{where}"
    if tried.verdict == "skip":
        line += f"\n        skipped: {tried.reason}"
    print(line, flush=True)


def cmd_bisect(args: argparse.Namespace) -> int:
    from twin.verify.bisect import bisect, check_options

    _tolerances(args)  # a bad preset or --tol is exit 2 before any work
    if args.json:
        check_output(args.json, ".json", option="--json", force=args.force)
    options = check_options(args.tolerance, args.tol, args.event_window)

    result = bisect(args.good, args.bad, args.paths, options, progress=_print_tried, announce=print)
    cached = sum(t.cached for t in result.tried)
    print(
        f"tried {len(result.tried)} of {len(result.path) + 1} commits "
        f"({len(result.tried) - cached} checked, {cached} from the cache .twin-bisect/)"
    )
    if result.outcome == "found":
        print(f"first bad commit: {result.first_bad.commit} {result.first_bad.subject}")
        for g in result.flipped:
            print(f"  {g['golden']}: {g['summary']}")
    elif result.outcome == "same":
        print(f"no change: {result.message}")
    else:
        print(f"undecided: {result.message}")
        for c in result.candidates:
            print(f"  {c}")
    if args.json:
        write_atomic(args.json, json.dumps(result.as_dict(), indent=2) + "\n")
    return result.exit_code


def add_bisect_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bisect",
        help="find the commit that changed what the robot does: the first one at which the "
        "goldens (as they are now) stop matching",
        description="Binary search between --good and --bad along the first-parent path. Each "
        "tried commit is checked out into a temporary worktree (your work tree, index, branch and "
        "stash are left alone), the goldens of your work tree are copied into it, and `twin check` "
        "runs there. Verdicts are cached in .twin-bisect/. Exit 0 found, 1 good and bad do not "
        "differ, 2 bad input, 3 skipped commits leave it undecided.",
    )
    p.add_argument("--good", required=True, metavar="REV", help="a commit at which they match")
    p.add_argument(
        "--bad", default="HEAD", metavar="REV", help="a later commit at which they differ (HEAD)"
    )
    p.add_argument(
        "paths",
        nargs="*",
        metavar="GOLDEN",
        help="goldens or folders of them, as `twin check` takes (default: recordings/)",
    )
    p.add_argument(
        "--json",
        default=None,
        metavar="FILE.json",
        help="also write the result, every tried commit's verdict included",
    )
    add_force_option(p, "the --json file")
    _add_tolerance_options(p, DEFAULT)
    p.set_defaults(func=cmd_bisect)
