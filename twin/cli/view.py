"""`twin view`: argument parsing and printing for showing a recording in Rerun (the work is in
record.rerun.viewer)."""

from __future__ import annotations

import argparse
import tempfile

from twin.cli.args import port, seconds
from twin.cli.record import add_force_option
from twin.record.outputs import check_output


def add_view_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="show a recording (.mcap or .rrd) in the Rerun viewer",
        description="Open a recording in Rerun's native viewer (an .mcap is drawn into a temporary "
        ".rrd first), serve the web viewer, convert to .rrd, or save a headless screenshot.",
    )
    p.add_argument("file", help="a recording: FILE.mcap or FILE.rrd")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer on 127.0.0.1 (offline) and print the URL that opens the "
        "recording",
    )
    mode.add_argument(
        "--rrd", metavar="OUT.rrd", help="convert an MCAP recording to a Rerun .rrd file and exit"
    )
    mode.add_argument(
        "--screenshot", metavar="OUT.png", help="render the viewer headless and save a PNG"
    )
    p.add_argument(
        "--port",
        type=port(allow_any=True),
        default=0,
        help="web viewer (HTTP) port with --web (default: a free one)",
    )
    p.add_argument(
        "--grpc-port",
        type=port(allow_any=True),
        default=0,
        help="port the recording is served from: the viewer's gRPC server, or with --web an HTTP "
        "server of the .rrd in twin view itself (default: a free one)",
    )
    p.add_argument(
        "--at",
        type=seconds("time", allow_zero=True),
        metavar="SECONDS",
        help="with --screenshot: the simulated time to show (default: the end of the first hold)",
    )
    add_force_option(p, "the --rrd or --screenshot file")
    p.set_defaults(func=cmd_view, interrupt=True)  # Ctrl-C even as a background job


def cmd_view(args: argparse.Namespace) -> int:
    from twin.record.rerun import viewer

    if args.rrd:
        # before any work
        check_output(args.rrd, ".rrd", inputs=[args.file], option="--rrd", force=args.force)
        frames = viewer.mcap_to_rrd(args.file, args.rrd)
        print(f"wrote {args.rrd}: {frames} frames")
        return 0
    if args.screenshot:  # before any work
        check_output(
            args.screenshot, ".png", inputs=[args.file], option="--screenshot", force=args.force
        )
    # Ctrl-C, SIGTERM and SIGHUP unwind through here (twin.signals): the viewer is stopped, the
    # folder removed.
    with tempfile.TemporaryDirectory(prefix="twin-view-") as tmp:
        rrd = viewer.as_rrd(args.file, tmp)  # a bad file is reported before a missing display
        if args.screenshot:
            shown_s, problems = viewer.screenshot(
                rrd, args.screenshot, tmp, at_s=args.at, grpc_port=args.grpc_port
            )
            when = "the end of the run" if shown_s is None else f"t = {shown_s:.3f} s"
            print(f"wrote {args.screenshot}: the viewer at {when}")
            for problem in problems:
                print(f"  view reported: {problem}")
            return 0
        if args.web:
            return viewer.serve_web(
                rrd,
                tmp,
                web_port=args.port,
                grpc_port=args.grpc_port,
                on_ready=lambda url: print(
                    f"serving the web viewer at {url} (Ctrl-C to stop)", flush=True
                ),
            )
        return viewer.open_native(rrd, tmp, grpc_port=args.grpc_port)
