"""The `twin serve` subcommand's arguments (the `twin` CLI registers it; the server lives in
server.py)."""

from __future__ import annotations

import argparse

from twin.cli.args import add_twin_options, port, twin_config, whole_number
from twin.cli.record import add_record_options, record_paths
from twin.remote import DEFAULT_STEP_GRACE_S, STEP_GRACE_RANGE_S
from twin.remote.protocol import DEFAULT_MAX_HELD_BYTES

SERVE_HELP = """\
Serve CoppeliaSim's ZeroMQ remote API (protocol v2) so its official Python client
(coppeliasim-zmqremoteapi-client) and the legacy simx* calls of twin.remote.legacy drive the twin.

Time: --realtime (default, like CoppeliaSim) advances the twin with the wall clock times --speed,
so clients that time.sleep between calls work; a client that calls sim.setStepping(True) gets
stepped behaviour. --stepped advances only on sim.step() (every stepping client must ask);
a stepping client silent for --step-grace seconds (default 10) no longer holds the others back.
Runs: the scene waits stopped until a client calls sim.startSimulation(); sim.stopSimulation()
ends the run and resets the scene. Each run is recorded (default runs/remote_<robot>.mcap;
--record NAME.mcap, --no-record): the first to NAME.mcap, the next to NAME-2.mcap, NAME-3.mcap,
... (each printed when it is finalized). An existing NAME.mcap is refused before the server
starts unless --force is given; the later runs' NAME-2.mcap, ... replace files of those names.
"""


def add_serve_command(sub) -> None:
    p = sub.add_parser(
        "serve",
        help="serve CoppeliaSim's ZeroMQ remote API (drive the twin from its clients)",
        description=SERVE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_twin_options(p, gui=False)
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1, loopback only)",
    )
    p.add_argument(
        "--port",
        type=port(allow_any=True),
        default=23000,
        help="port (default 23000, CoppeliaSim's; 0: any free port)",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--realtime",
        dest="mode",
        action="store_const",
        const="realtime",
        help="advance with the wall clock (default)",
    )
    mode.add_argument(
        "--stepped",
        dest="mode",
        action="store_const",
        const="stepped",
        help="advance only on sim.step()",
    )
    p.set_defaults(mode="realtime")
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="--realtime: simulated seconds per wall second (default 1)",
    )
    low, high = STEP_GRACE_RANGE_S
    p.add_argument(
        "--step-grace",
        type=float,
        default=DEFAULT_STEP_GRACE_S,
        metavar="SECONDS",
        help="a stepping client silent this long no longer holds back the others' sim.step() "
        f"(default {DEFAULT_STEP_GRACE_S:g}; {low:g}..{high:g})",
    )
    p.add_argument(
        "--max-held-mib",
        type=whole_number(1),
        default=DEFAULT_MAX_HELD_BYTES >> 20,
        metavar="MIB",
        help="the most the server holds of requests not yet complete, all connections together "
        f"(default {DEFAULT_MAX_HELD_BYTES >> 20} MiB); over it, the connection holding the most "
        "is closed",
    )
    p.add_argument(
        "--start", action="store_true", help="start the simulation at launch, like pressing Play"
    )
    add_record_options(p, record_by_default=True, default_stem="remote_<robot>")
    p.set_defaults(func=cmd_serve)


def cmd_serve(args: argparse.Namespace) -> int:
    from twin.remote.server import serve

    config = twin_config(args)
    mcap_path, rrd_path = record_paths(args, f"remote_{config.profile.name}")
    return serve(
        config,
        host=args.host,
        port=args.port,
        mode=args.mode,
        speed=args.speed,
        step_grace_s=args.step_grace,
        mcap_path=str(mcap_path) if mcap_path else None,
        rrd_path=str(rrd_path) if rrd_path else None,
        rate=args.rate,
        start=args.start,
        log=lambda line: print(line, flush=True),
        max_held_bytes=args.max_held_mib << 20,
    )
