"""`twin export --format ros2`, and `twin diff` when a side is a ROS 2 bag: parsing their options
and printing only (the writing is in twin.ros2.export, the reading in twin.ros2.bags, the judging
in twin.compare.samples).
"""

from __future__ import annotations

import argparse
import math

from twin.compare.tolerances import DEFAULT
from twin.model.errors import ConfigError

BAG_PRESET = "physical"  # a robot's log beside the twin: physical units, not the twin's own noise


def add_bag_options(p: argparse.ArgumentParser) -> None:
    """--joint-map and --time-offset, for a diff where a side is a ROS 2 bag; --tolerance's
    default is then physical (diff_with_bag fills it in)."""
    p.set_defaults(tolerance=None)
    p.add_argument(
        "--joint-map",
        action="append",
        default=[],
        metavar="ROBOT=TWIN",
        help="a ROS 2 bag's joint name and the twin's name for it (repeatable); with a bag, "
        "--tolerance defaults to physical",
    )
    p.add_argument(
        "--time-offset",
        type=float,
        default=None,
        metavar="S",
        help="with a ROS 2 bag: the candidate runs S seconds after the golden, from their first "
        "samples (default: found from the first motion and the best fit)",
    )


def _log(path: str, joint_map: dict[str, str]):
    """A side as a JointLog and which of its joints are revolute (a twin run knows; a bag not)."""
    from twin.compare.metrics import REVOLUTE
    from twin.record.mcap.reader import load
    from twin.record.mcap.scan import is_bag
    from twin.ros2.bags import read_bag, run_log

    if is_bag(path):
        return read_bag(path).renamed(joint_map), {}
    log = run_log(load(path))
    return log, {name: bool(REVOLUTE[k]) for k, name in enumerate(log.names)}


def diff_with_bag(args: argparse.Namespace, tolerances) -> int | None:
    """The exit code of `twin diff` when a side is a ROS 2 bag (a joint-log comparison, judged by
    `tolerances(args)`, the physical preset unless --tolerance names one); None when neither is
    (then --joint-map and --time-offset are refused, and the preset left unsaid is DEFAULT)."""
    from twin.compare.samples import compare_logs, render_log_comparison
    from twin.model.joint_log import parse_joint_map
    from twin.record.mcap.scan import is_bag

    bags = [p for p in (args.golden, args.candidate) if is_bag(p)]
    if not bags:
        for option, value in (("--joint-map", args.joint_map), ("--time-offset", args.time_offset)):
            if value not in (None, []):
                raise ConfigError(f"{option} is for a ROS 2 bag; neither input is one")
        args.tolerance = args.tolerance or DEFAULT
        return None
    args.tolerance = args.tolerance or BAG_PRESET
    for option in ("report", "rrd", "html"):
        if getattr(args, option, None):
            raise ConfigError(
                f"--{option} is for two twin recordings; a ROS 2 bag is compared "
                "as a joint log, printed only"
            )
    if args.time_offset is not None and not math.isfinite(args.time_offset):
        raise ConfigError(f"--time-offset {args.time_offset} is invalid; expected seconds")
    joint_map = parse_joint_map(args.joint_map)
    (a, rev_a), (b, rev_b) = _log(args.golden, joint_map), _log(args.candidate, joint_map)
    result = compare_logs(
        a, b, tolerances(args), revolute={**rev_b, **rev_a}, lag_s=args.time_offset
    )
    text = render_log_comparison(result)
    if args.quiet:  # the verdict, the alignment and the first divergence
        head = text.splitlines()[:4]
        text = "\n".join(line for line in head if not line.startswith("joint|frame"))
    print(text)
    return result.exit_code


def cmd_export_ros2(files: list[str], output: str, *, force: bool) -> int:
    """Each recording written as a bag; one line per bag."""
    from twin.ros2.export import export_bags

    for bag, messages, topics in export_bags(files, output, force=force):
        print(f"wrote {bag}: ROS 2 bag, {messages} messages on {topics} topics")
    return 0
