"""`twin view`: argument parsing and printing for showing a recording in Rerun (the work is in record.viewer)."""

from __future__ import annotations

import argparse
import math
import tempfile

from twin.cli_args import port
from twin.outputs import check_output

DEFAULT_WEB_PORT = 9090


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"time {text!r} is invalid; expected seconds of simulated time >= 0")
    return value


def add_view_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="show a recording (.mcap or .rrd) in the Rerun viewer",
                       description="Open a recording in Rerun's native viewer (an .mcap is drawn into a temporary "
                                   ".rrd first), serve the web viewer, convert to .rrd, or save a headless screenshot.")
    p.add_argument("file", help="a recording: FILE.mcap or FILE.rrd")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--web", action="store_true", help="serve the web viewer on localhost (offline)")
    mode.add_argument("--rrd", metavar="OUT.rrd", help="convert an MCAP recording to a Rerun .rrd file and exit")
    mode.add_argument("--screenshot", metavar="OUT.png", help="render the viewer headless and save a PNG")
    p.add_argument("--port", type=port(), default=DEFAULT_WEB_PORT,
                   help=f"web viewer port with --web (default {DEFAULT_WEB_PORT})")
    p.add_argument("--at", type=_seconds, metavar="SECONDS",
                   help="with --screenshot: the simulated time to show (default: the end of the first hold)")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    from twin.record import viewer

    if args.rrd:
        check_output(args.rrd, ".rrd", inputs=[args.file], option="--rrd")  # before any work
        frames = viewer.mcap_to_rrd(args.file, args.rrd)
        print(f"wrote {args.rrd}: {frames} frames")
        return 0
    with tempfile.TemporaryDirectory(prefix="twin-view-") as tmp:
        rrd = viewer.as_rrd(args.file, tmp)
        if args.screenshot:
            shown_s, problems = viewer.screenshot(rrd, args.screenshot, at_s=args.at)
            when = "the end of the run" if shown_s is None else f"t = {shown_s:.3f} s"
            print(f"wrote {args.screenshot}: the viewer at {when}")
            for problem in problems:
                print(f"  view reported: {problem}")
            return 0
        if args.web:
            print(f"serving the web viewer at http://127.0.0.1:{args.port} (Ctrl-C to stop)")
            return viewer.serve_web(rrd, args.port)
        return viewer.open_native(rrd)
