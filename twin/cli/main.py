"""The `twin` command: argument parsing and printing only."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import TYPE_CHECKING

from twin.cli.args import (
    add_param_option,
    add_scene_options,
    add_twin_options,
    camera_specs,
    params_dict,
    scene_config,
    seconds,
    twin_config,
    whole_number,
)
from twin.cli.bisect import add_bisect_command
from twin.cli.compare import add_compare_commands
from twin.cli.export import add_export_command
from twin.cli.record import add_record_commands, add_record_options, record_paths
from twin.cli.search import add_search_command
from twin.cli.serve import add_serve_command
from twin.cli.sweep import add_sweep_command
from twin.cli.view import add_view_command
from twin.model.errors import ConfigError, TwinError
from twin.model.sink import Sink
from twin.signals import Terminated, stop_signals_raise

if TYPE_CHECKING:
    from twin.sim.twin import Twin

DEFAULT_CYCLES = 2
BROKEN_PIPE_EXIT = 141  # 128 + SIGPIPE: standard output was closed by its reader


def cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    # here, not at the top: every `twin` command parses with this module, and only `run` steps a
    # twin (the suite starts hundreds of twin processes; each import left out is CPU saved)
    from twin.record import open_recorders  # only record/ touches mcap and rerun
    from twin.sim.twin import Twin
    from twin.sim.world import engine_versions
    from twin.tasks import TimeLimit, resolve, run_task
    from twin.verify.check import task_run

    fn = resolve(args.task)
    config = scene_config(twin_config(args), args, fn, args.task)
    params = run_params(fn, args)
    mcap_path, rrd_path = record_paths(args, f"{Path(args.task).stem}_{config.profile.name}")
    # a task file by its path relative to the recording
    run = task_run(args.task, params, mcap_path)
    if args.timeout is not None:
        run["timeout_s"] = args.timeout  # twin check re-runs the task with the same bound
    summary = _Summary()
    limit = [TimeLimit(args.timeout)] if args.timeout is not None else []
    twin, wall_s = None, 0.0
    # The summary is printed once the files are finished: output that cannot be written (a pipe into
    # `head` that stopped reading) must not turn a good run's recording into an error, nor leave the
    # twin (and its camera process) open.
    try:
        with open_recorders(config, run, mcap_path=mcap_path, rrd_path=rrd_path, rate=args.rate,
                            engine=engine_versions()) as sinks:
            # the limit last: recorders see its frame
            twin = Twin(config, gui=args.gui, sinks=[summary, *sinks, *limit])
            wall0 = time.perf_counter()
            try:
                run_task(twin, fn, params)
            finally:
                wall_s = time.perf_counter() - wall0
                twin.close()
    finally:
        if twin is not None:
            _print_summary(twin, summary, wall_s)
    for path in (mcap_path, rrd_path):  # the files are finished only now
        if path is not None:
            print(f"recorded {path}")
    return 0


def run_params(fn, args: argparse.Namespace) -> dict:
    """The task parameters of `twin run`: --param pairs and --cycles, checked against the task's
    signature (an unknown name is an error, exit 2). A task that takes `cycles` gets 2 when neither
    names it, as before --param existed."""
    from twin.tasks import check_params, task_params

    params = params_dict(args.param)
    if args.cycles is not None:
        if "cycles" in params:
            raise ConfigError(
                "--cycles and --param cycles=... are both given; expected one of them"
            )
        params["cycles"] = args.cycles
    elif "cycles" not in params and "cycles" in (task_params(fn) or {}):
        params["cycles"] = DEFAULT_CYCLES
    return check_params(fn, params, args.task)


class _Summary(Sink):
    """A sink that keeps the events for the closing summary."""

    def __init__(self) -> None:
        self.events = []

    def on_event(self, event) -> None:
        self.events.append(event)


def _print_summary(twin: Twin, summary: _Summary, wall_s: float) -> None:
    sim_s = twin.t_s
    print(
        f"robot {twin.profile.name}: {twin.step_index} steps, simulated {sim_s:.3f} s, "
        f"wall {wall_s:.3f} s, "
        f"real-time factor {sim_s / wall_s if wall_s > 0 else float('inf'):.1f}x"
    )
    counts: dict[str, int] = {}
    for ev in summary.events:
        counts[ev.kind] = counts.get(ev.kind, 0) + 1
    print("events: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    for ev in summary.events:
        if ev.kind in (
            "attach",
            "release",
            "break",
            "suction_empty",
            "out_of_reach",
            "placed",
            "task_error",
            "settle_timeout",
            "joint_limit",
        ):
            print(f"  t={ev.t_ns * 1e-9:8.3f} s  {ev.kind:<14} {ev.body:<6} {ev.message}")
    for obj, pose in zip(twin.config.objects, twin.frame.object_poses, strict=True):
        print(
            f"{obj.name} final pose: x {pose[0]:+.4f} y {pose[1]:+.4f} z {pose[2]:+.4f} m, "
            f"q ({pose[3]:+.4f}, {pose[4]:+.4f}, {pose[5]:+.4f}, {pose[6]:+.4f})"
        )
    placed = [ev for ev in summary.events if ev.kind == "placed"]
    errors = [e for e in (_error_m(ev) for ev in placed) if e is not None]
    unmeasured = len(placed) - len(errors)
    if errors:  # a task's own `placed` event may carry no error figure: counted, never a crash
        print(
            f"placement error: worst {max(errors) * 1000:.2f} mm over {len(errors)} cycle(s)"
            + (f"; {unmeasured} more placed (no error figure)" if unmeasured else "")
        )
    elif placed:
        print(f"placement error: {unmeasured} placed (no error figure)")


def _error_m(event) -> float | None:
    """A `placed` event's error_m when it is a finite number of metres, else None (missing, null,
    text)."""
    value = event.data.get("error_m") if isinstance(event.data, dict) else None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        value = float(value)
    except OverflowError:  # an integer too large for a float
        return None
    return value if math.isfinite(value) else None


def cmd_teleop(args: argparse.Namespace) -> int:
    from twin.teleop.session import TeleopOptions, run_teleop, summary_lines

    mcap, rrd = record_paths(args, f"teleop_{args.robot}")
    session = run_teleop(
        TeleopOptions(
            robot=args.robot,
            rate_hz=args.rate_hz,
            gui=args.gui,
            keymap_path=args.keymap or "",
            keys=args.keys,
            key_interval_s=args.key_interval,
            record_path=str(mcap) if mcap else None,
            rrd_path=str(rrd) if rrd else None,
            record_rate=args.rate,
            cameras=camera_specs(args),
        )
    )
    for line in summary_lines(session):
        print(line)
    return 0


def _add_teleop_parser(sub) -> None:
    p = sub.add_parser(
        "teleop",
        help="drive the robot from the keyboard (terminal screen, window, or --keys)",
        description="Keyboard teleoperation. Quit: Esc, Ctrl-C, Ctrl-D, and q unless the key map "
        "binds q (seed000's elbow). Every key press is recorded and replayable.",
    )
    add_twin_options(p)
    add_record_options(p, record_by_default=False)
    p.add_argument(
        "--keymap",
        metavar="FILE",
        help="your own key map (.toml or .json); default: the robot's map",
    )
    p.add_argument(
        "--keys",
        metavar="KEYS",
        help='scripted keys, e.g. "d*30 e 8 wait*2 s" (a character or a '
        "name like up/down/left/right/space; wait: no key; *N repeats), run in simulated time",
    )
    p.add_argument(
        "--key-interval",
        metavar="SECONDS",
        type=float,
        default=0.5,
        help="simulated time after each scripted key (default 0.5 s)",
    )
    p.set_defaults(func=cmd_teleop)


class _OneLineErrors(argparse.ArgumentParser):
    """Usage errors as one line (like every other error) and exit code 2; sub-commands inherit
    it."""

    def error(self, message: str):
        self.exit(2, f"twin: error: {message} (see `{self.prog} --help`)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineErrors(
        prog="twin", description="Record-and-replay digital twin of the MTB SCARA robot"
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a task (built-in name or path/to/task.py)")
    p.add_argument("task")
    add_twin_options(p)
    p.add_argument(
        "--cycles",
        type=whole_number(1),
        default=None,
        help=f"pick-and-place cycles (default {DEFAULT_CYCLES} for a task that takes cycles)",
    )
    add_param_option(p)
    add_scene_options(p)
    p.add_argument(
        "--timeout",
        type=seconds("--timeout", allow_zero=False),
        metavar="SECONDS",
        help="end the task with an error (exit 1) once it passes this much simulated time",
    )
    add_record_options(p)
    p.set_defaults(func=cmd_run)
    _add_teleop_parser(sub)
    add_compare_commands(sub)
    add_bisect_command(sub)
    add_record_commands(sub)
    add_serve_command(sub)
    add_sweep_command(sub)
    add_search_command(sub)
    add_view_command(sub)
    add_export_command(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one `twin` command; returns its exit code (usage errors and --help included)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help (0) or a usage error (2), already printed
        return done.code if isinstance(done.code, int) else 2
    try:
        # SIGTERM and SIGHUP unwind like Ctrl-C: recordings are finalized
        with stop_signals_raise(interrupt=getattr(args, "interrupt", False)):
            return args.func(args)
    except TwinError as err:
        print(f"twin: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print("twin: interrupted", file=sys.stderr)
        return 130
    except Terminated as stop:
        print(f"twin: stopped by {stop.name}", file=sys.stderr)
        return stop.exit_code
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading: what the shell
        # reports for a program SIGPIPE ended
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return BROKEN_PIPE_EXIT


if __name__ == "__main__":
    sys.exit(main())
