"""`twin export`: recordings out as Parquet, CSV, a LeRobot v3.0 dataset (the work is in
twin.export) or ROS 2 bags (twin.ros2).

Exit codes: 0 written; 1 with --verify, a recording whose replay is not exact was left out (the rest
is written; nothing is written if none is left); 2 bad input, checked before any work.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from twin.cli.args import whole_number
from twin.export.episodes import MAX_FPS
from twin.model.errors import ConfigError, TwinError

FORMATS = ("parquet", "csv", "lerobot", "ros2")


class _LeftOut(TwinError):
    """--verify left a recording out (its replay was not exact)."""

    exit_code = 1


def add_export_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="recordings as Parquet, CSV (one row per frame), a LeRobot v3.0 dataset or ROS 2 bags",
        description="parquet/csv: one recording's frames (or --table events|commands) in one file. "
        "lerobot: every recording (or pick-place cycle) an episode, resampled to --fps. "
        "ros2: each recording a ROS 2 bag (rosbag2's MCAP storage and metadata.yaml).",
    )
    p.add_argument(
        "files", nargs="+", metavar="FILE.mcap", help="recordings (parquet and csv: exactly one)"
    )
    p.add_argument("--format", required=True, choices=FORMATS, help="parquet, csv, lerobot or ros2")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="FILE.parquet, FILE.csv, the dataset's folder (new, or empty) for lerobot; for ros2 "
        "the bag's folder (new, or empty), or with several recordings a folder of bags named "
        "after them",
    )
    p.add_argument(
        "--table",
        choices=("frames", "events", "commands"),
        default=None,
        help="parquet/csv: which table (default frames: one row per recorded frame)",
    )
    p.add_argument(
        "--fps",
        type=whole_number(1),
        default=None,
        metavar="N",
        help=f"lerobot: frames per second of the dataset (a whole number; required), at most the "
        f"recordings' physics rate (240 by default; never above {MAX_FPS})",
    )
    p.add_argument(
        "--episodes",
        choices=("recording", "cycles"),
        default=None,
        help="lerobot: one episode per recording (default) or per pick-place cycle",
    )
    p.add_argument(
        "--task",
        default=None,
        metavar="TEXT",
        help="lerobot: the episodes' task text (default: each recording's task name)",
    )
    p.add_argument(
        "--verify",
        action="store_true",
        help="lerobot: replay each recording first; export only those whose replay is exact",
    )
    p.add_argument(
        "--force",
        "--overwrite",
        dest="force",
        action="store_true",
        help="replace an existing -o file (parquet, csv), dataset folder (lerobot: one holding "
        "meta/info.json) or bag (ros2: one holding metadata.yaml) once the new one is complete; "
        "without it, an existing one is refused before any work",
    )
    p.set_defaults(func=cmd_export, interrupt=True)  # Ctrl-C even as a background job


def cmd_export(args: argparse.Namespace) -> int:
    if args.format == "lerobot":
        return _export_lerobot(args)
    if args.format == "ros2":
        from twin.cli.ros2 import cmd_export_ros2

        options = ("--table", "--fps", "--episodes", "--task", "--verify")
        _refuse(args, options, "--format parquet, csv and lerobot")
        return cmd_export_ros2(args.files, args.output, force=args.force)
    return _export_table(args)


def _refuse(args: argparse.Namespace, options: tuple[str, ...], why: str) -> None:
    for option in options:
        value = getattr(args, option.lstrip("-").replace("-", "_"))
        if value not in (None, False):
            raise ConfigError(f"{option} is for {why}; --format {args.format} does not take it")


def _export_table(args: argparse.Namespace) -> int:
    from twin.export.files import FORMATS as SUFFIXES
    from twin.export.files import write_table
    from twin.export.sources import check_commands
    from twin.record.mcap.reader import load
    from twin.record.outputs import check_output

    _refuse(args, ("--fps", "--episodes", "--task", "--verify"), "--format lerobot")
    if len(args.files) != 1:
        raise ConfigError(
            f"--format {args.format} writes one recording; got {len(args.files)} files "
            "(export each on its own, or use --format lerobot)"
        )
    out = check_output(
        args.output, SUFFIXES[args.format], inputs=args.files, option="output", force=args.force
    )
    table = args.table or "frames"
    rec = load(args.files[0])
    # the frames table reads them (suction.command); a malformed one is exit 2 as in replay
    check_commands(rec)
    rows = write_table(rec, out, args.format, table)
    print(f"wrote {out}: {rows} rows ({table})")
    return 0


def _export_lerobot(args: argparse.Namespace) -> int:
    from twin.export.pipeline import export_lerobot

    _refuse(args, ("--table",), "--format parquet and csv")
    if args.fps is None:
        raise ConfigError("--format lerobot needs --fps N (a whole number of frames per second)")
    # before loading anything; each recording's own physics rate is checked once loaded
    if args.fps > MAX_FPS:
        raise ConfigError(
            f"--fps {args.fps} is above {MAX_FPS}, the fastest physics rate a recording "
            f"has; expected "
            "at most the recordings' physics rate (240 by default)"
        )
    written, sources = export_lerobot(
        args.files,
        Path(args.output),
        args.fps,
        mode=args.episodes or "recording",
        task=args.task,
        verify_first=args.verify,
        overwrite=args.force,
        say=print,
    )
    left_out = sum(1 for s in sources if s.verified is False)
    if written is None:
        raise _LeftOut(
            f"no recording to export: the replay of each differs from it (--verify); "
            f"nothing written to "
            f"{args.output!r}"
        )
    videos = f", videos {', '.join(written.video_keys)}" if written.video_keys else ", no camera"
    print(
        f"wrote {written.path}: {written.episodes} episode(s), {written.frames} frames "
        f"at {args.fps} fps{videos}"
    )
    if left_out:
        raise _LeftOut(
            f"{left_out} of {len(sources)} recording(s) left out: their replay is not exact"
        )
    return 0
