"""The `twin` command: argument parsing and printing only."""

from __future__ import annotations

import argparse
import sys
import time

from twin.config import TwinConfig, dt_ns_from_hz
from twin.errors import TwinError
from twin.profiles import get_profile
from twin.tasks import accepted_params, resolve, run_task
from twin.twin import Twin


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= 1")
    return value


def _add_twin_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default="mtb", help="profile: mtb, seed000..seed003, or a profile file")
    p.add_argument("--rate-hz", type=float, default=240.0, help="physics rate (default 240 Hz)")
    p.add_argument("--gui", action="store_true", help="open the PyBullet window")


def _config(args: argparse.Namespace) -> TwinConfig:
    return TwinConfig(profile=get_profile(args.robot), dt_ns=dt_ns_from_hz(args.rate_hz))


def cmd_run(args: argparse.Namespace) -> int:
    fn = resolve(args.task)
    config = _config(args)
    params = accepted_params(fn, {"cycles": args.cycles})
    summary = _Summary()
    twin = Twin(config, gui=args.gui, sinks=[summary])
    wall0 = time.perf_counter()
    try:
        run_task(twin, fn, params)
    finally:
        wall_s = time.perf_counter() - wall0
        _print_summary(twin, summary, wall_s)
        twin.close()
    return 0


class _Summary:
    """A sink that keeps the events for the closing summary."""

    def __init__(self) -> None:
        self.events = []

    def on_frame(self, frame) -> None:
        pass

    def on_command(self, command) -> None:
        pass

    def on_event(self, event) -> None:
        self.events.append(event)


def _print_summary(twin: Twin, summary: _Summary, wall_s: float) -> None:
    sim_s = twin.t_s
    print(f"robot {twin.profile.name}: {twin.step_index} steps, simulated {sim_s:.3f} s, wall {wall_s:.3f} s, "
          f"real-time factor {sim_s / wall_s if wall_s > 0 else float('inf'):.1f}x")
    counts: dict[str, int] = {}
    for ev in summary.events:
        counts[ev.kind] = counts.get(ev.kind, 0) + 1
    print("events: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    for ev in summary.events:
        if ev.kind in ("attach", "release", "break", "suction_empty", "out_of_reach", "placed", "task_error",
                       "settle_timeout", "joint_limit"):
            print(f"  t={ev.t_ns * 1e-9:8.3f} s  {ev.kind:<14} {ev.body:<6} {ev.message}")
    for obj, pose in zip(twin.config.objects, twin.frame.object_poses, strict=True):
        print(f"{obj.name} final pose: x {pose[0]:+.4f} y {pose[1]:+.4f} z {pose[2]:+.4f} m, "
              f"q ({pose[3]:+.4f}, {pose[4]:+.4f}, {pose[5]:+.4f}, {pose[6]:+.4f})")
    placed = [ev for ev in summary.events if ev.kind == "placed"]
    if placed:
        worst = max(ev.data["error_m"] for ev in placed)
        print(f"placement error: worst {worst * 1000:.2f} mm over {len(placed)} cycle(s)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="twin", description="Record-and-replay digital twin of the MTB SCARA robot")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a task (built-in name or path/to/task.py)")
    p.add_argument("task")
    _add_twin_options(p)
    p.add_argument("--cycles", type=_positive_int, default=2, help="pick-and-place cycles (default 2)")
    p.set_defaults(func=cmd_run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except TwinError as err:
        print(f"twin: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print("twin: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
