"""Recording options shared by `twin run`, `teleop` and `serve`, and the `twin info` and `twin
recover` commands: argument parsing and printing only."""

from __future__ import annotations

import argparse
from pathlib import Path

from twin.cli.args import whole_number
from twin.model.errors import RecordingError
from twin.record.outputs import DEFAULT_FOLDER, check_output, partial_path


def add_record_options(
    p: argparse.ArgumentParser,
    *,
    record_by_default: bool = True,
    default_stem: str = "<task>_<robot>",
) -> None:
    """--record FILE.mcap, --no-record (when recording is on by default), --rrd FILE.rrd, --rate N.
    default_stem: the default file's name as the help shows it (record_paths makes the real one)."""
    default_text = (
        f"default {DEFAULT_FOLDER}/{default_stem}.mcap"
        if record_by_default
        else "default: no MCAP file"
    )
    group = p.add_mutually_exclusive_group()
    group.add_argument(
        "--record", metavar="FILE.mcap", help=f"record the run to this MCAP file ({default_text})"
    )
    if record_by_default:
        group.add_argument(
            "--no-record", action="store_true", help="do not write an MCAP recording"
        )
    p.add_argument(
        "--rrd",
        metavar="FILE.rrd",
        help="also write a Rerun recording (a view, regenerable from MCAP)",
    )
    p.add_argument(
        "--rate",
        type=whole_number(1),
        default=1,
        metavar="N",
        help="MCAP: keep every Nth physics step (default 1: every step; the last step is "
        "always kept); "
        "the .rrd view keeps every step",
    )
    add_force_option(p, "the --record and --rrd files")
    p.set_defaults(record_by_default=record_by_default)


def add_force_option(p: argparse.ArgumentParser, what: str) -> None:
    """--force: replace `what` when it exists (without it, an existing one is refused, exit 2,
    before any work); the new file is written beside it and renamed over it when complete."""
    p.add_argument(
        "--force",
        action="store_true",
        help=f"replace {what} if it exists (without it an existing one is refused before any "
        "work); the old one stays until the new one is complete",
    )


def record_paths(args: argparse.Namespace, default_stem: str) -> tuple[Path | None, Path | None]:
    """The MCAP and Rerun paths the options ask for (the MCAP default is runs/<default_stem>.mcap),
    checked before any work (suffix, not a folder, the folder exists, and no file there unless
    --force). Only runs/ is created when
    missing (the default's folder, or one the user names: twin.record.outputs.make_default_folder);
    any other folder must exist."""
    mcap = args.record
    if (
        mcap is None
        and getattr(args, "record_by_default", False)
        and not getattr(args, "no_record", False)
    ):
        mcap = str(Path(DEFAULT_FOLDER) / f"{default_stem}.mcap")
    force = bool(getattr(args, "force", False))
    mcap_path = (
        check_output(mcap, ".mcap", option="recording", force=force) if mcap is not None else None
    )
    rrd_path = (
        check_output(args.rrd, ".rrd", option="recording", force=force)
        if args.rrd is not None
        else None
    )
    return mcap_path, rrd_path


def cmd_info(args: argparse.Namespace) -> int:
    from twin.record.mcap.info import format_info, read_info

    partial = partial_path(args.file)
    if not Path(args.file).exists() and partial.is_file():
        raise RecordingError(
            f"recording {args.file!r} does not exist, but {str(partial)!r} does: the "
            f"unfinished file "
            f"of a run that was killed (or is still running); `twin recover {args.file}` "
            f"restores it"
        )
    info = read_info(args.file, keep_events=args.events)
    for line in format_info(info, all_events=args.events):
        print(line)
    if not info.intact:
        raise RecordingError(
            f"recording {args.file!r} is not finalized: {info.problem}; "
            f"`twin recover {args.file} -o FIXED.mcap` restores its readable part"
        )
    if info.problems:  # printed above, each on its own line; the error names the first and how many
        more = (
            f" (and {len(info.problems) - 1} more problem(s) listed above)"
            if len(info.problems) > 1
            else ""
        )
        raise RecordingError(f"recording {args.file!r}: {info.problems[0]}{more}")
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    from twin.record.mcap.recover import recover

    report = recover(args.file, args.output, force=args.force)
    for line in report.lines():
        print(line)
    return 0


def add_record_commands(sub) -> None:
    p = sub.add_parser(
        "info",
        help="describe a recording: duration, channels, events, metadata, finalized or not",
        description="Exit code 0 for a complete twin recording; 2 for a missing, unfinished or "
        "foreign file, or one with any unreadable part (the report says what it could read).",
    )
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument(
        "--events", action="store_true", help="also list every event with its time, step and data"
    )
    p.set_defaults(func=cmd_info)
    p = sub.add_parser(
        "recover",
        help="restore the readable part of a recording cut short (crash, kill -9)",
        description="Reads up to the first damaged record and writes a complete MCAP file. A run "
        "writes NAME.mcap.partial and renames it to NAME.mcap when it ends; a killed run "
        "leaves the .partial file: `twin recover NAME.mcap` finds it and writes NAME.mcap.",
    )
    p.add_argument(
        "file",
        metavar="BROKEN.mcap",
        help="the cut-short file; for a killed run, its NAME.mcap (its NAME.mcap.partial is used)",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="FIXED.mcap",
        help="where to write the restored file (default, for a killed run's .partial file: "
        "the NAME.mcap "
        "it was meant to become, if that does not exist)",
    )
    add_force_option(p, "the -o file")
    p.set_defaults(func=cmd_recover)
