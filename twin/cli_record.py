"""Recording options shared by `twin run`, `teleop` and `serve`, and the `twin info` and `twin recover`
commands: argument parsing and printing only."""

from __future__ import annotations

import argparse
from pathlib import Path

from twin.cli_args import whole_number
from twin.errors import ConfigError, RecordingError

DEFAULT_FOLDER = "runs"


def add_record_options(p: argparse.ArgumentParser, *, record_by_default: bool = True) -> None:
    """--record FILE.mcap, --no-record (when recording is on by default), --rrd FILE.rrd, --rate N."""
    default_text = f"default {DEFAULT_FOLDER}/<task>_<robot>.mcap" if record_by_default else "default: no MCAP file"
    group = p.add_mutually_exclusive_group()
    group.add_argument("--record", metavar="FILE.mcap", help=f"record the run to this MCAP file ({default_text})")
    if record_by_default:
        group.add_argument("--no-record", action="store_true", help="do not write an MCAP recording")
    p.add_argument("--rrd", metavar="FILE.rrd", help="also write a Rerun recording (a view, regenerable from MCAP)")
    p.add_argument("--rate", type=whole_number(1), default=1, metavar="N",
                   help="MCAP: keep every Nth physics step (default 1: every step; the last step is always kept); "
                        "the .rrd view keeps every step")
    p.set_defaults(record_by_default=record_by_default)


def record_paths(args: argparse.Namespace, default_stem: str) -> tuple[Path | None, Path | None]:
    """The MCAP and Rerun paths the options ask for (the MCAP default is runs/<default_stem>.mcap)."""
    mcap = args.record
    if mcap is None and getattr(args, "record_by_default", False) and not getattr(args, "no_record", False):
        mcap = str(Path(DEFAULT_FOLDER) / f"{default_stem}.mcap")
    rrd = args.rrd
    for path, suffix in ((mcap, ".mcap"), (rrd, ".rrd")):
        if path is not None and Path(path).suffix != suffix:
            raise ConfigError(f"recording path {path!r} should end in {suffix}")
    if mcap is not None and rrd is not None and Path(mcap).resolve() == Path(rrd).resolve():
        raise ConfigError(f"the MCAP and Rerun recordings cannot share the path {mcap!r}")
    return (Path(mcap) if mcap is not None else None), (Path(rrd) if rrd is not None else None)


def cmd_info(args: argparse.Namespace) -> int:
    from twin.record.info import describe, format_info

    info = describe(args.file)
    for line in format_info(info):
        print(line)
    if not info.intact:
        raise RecordingError(f"recording {args.file!r} is not finalized: {info.problem}; "
                             f"`twin recover {args.file} -o FIXED.mcap` restores its readable part")
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    from twin.record.recover import recover

    report = recover(args.file, args.output)
    for line in report.lines():
        print(line)
    return 0


def add_record_commands(sub) -> None:
    p = sub.add_parser("info", help="describe a recording: duration, channels, events, metadata, finalized or not",
                       description="Exit code 0 for a complete file, 2 for a missing, unreadable or unfinished one.")
    p.add_argument("file", metavar="FILE.mcap")
    p.set_defaults(func=cmd_info)
    p = sub.add_parser("recover", help="restore the readable part of a recording cut short (crash, kill -9)",
                       description="Reads up to the first damaged record and writes a complete MCAP file.")
    p.add_argument("file", metavar="BROKEN.mcap")
    p.add_argument("-o", "--output", required=True, metavar="FIXED.mcap", help="where to write the restored file")
    p.set_defaults(func=cmd_recover)
