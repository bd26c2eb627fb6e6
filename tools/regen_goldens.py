#!/usr/bin/env python3
"""Remake the golden recordings in recordings/ from the current code.

    python tools/regen_goldens.py            # every golden
    python tools/regen_goldens.py NAME ...   # only these (e.g. pick_place_mtb)
    python tools/regen_goldens.py --list     # what would be made, and how

A task golden is one task run recorded through the same recorder as `twin run --record`; its MCAP
metadata holds the whole TwinConfig and the task with its parameters, so `twin check` re-runs it
from the file alone. Identical code gives byte-identical files (the writer stamps no wall time).
A session golden is one run of a report's own step-5 program (tests/fixtures/seed_clients/) against
`twin serve --realtime` at speed 1, as its author ran it; `twin check` replays its Commands. Its
steps follow the wall clock, so remaking one gives a new file (the same program, other timings).
Run this only when a change in behaviour is intended, then review `twin diff` against the old files.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.model.config import SceneObject, SuctionParams, TwinConfig
from twin.model.errors import TwinError
from twin.model.profiles import PROFILES
from twin.record import open_recorders
from twin.sim.world import engine_versions
from twin.verify.check import record_task

ROOT = Path(__file__).resolve().parent.parent
RECORDINGS = ROOT / "recordings"
CLIENTS = ROOT / "tests" / "fixtures" / "seed_clients"
# every physics step: exact checks see every step (about 0.5 MB per 10 s of simulated time)
RATE_STEPS = 1


@dataclass(frozen=True)
class Golden:
    name: str
    config: TwinConfig
    task: str
    params: dict
    how: str
    # keep every Nth step (commands and events are kept at every step whatever it is)
    rate: int = RATE_STEPS


def goldens() -> list[Golden]:
    out = [
        Golden(
            f"pick_place_{name}",
            TwinConfig(profile=profile),
            "pick_place",
            {"cycles": 2},
            f"pick_place, 2 cycles, robot {name}, default scene (one 50 mm, 0.1 kg box "
            f"at (0.2, 0.7))",
        )
        for name, profile in sorted(PROFILES.items())
    ]
    heavy = TwinConfig(
        objects=(SceneObject("box", mass_kg=0.5),), suction=SuctionParams(infinite_strength=False)
    )
    out += [  # each report's own step-4 Lua loop on its own scene (docs/seed-conventions.md)
        Golden(
            "seed000_seed000",
            TwinConfig(profile=PROFILES["seed000"]),
            "seed000",
            {"cycles": 1},
            "task seed000 (report 000's Lua loop), 1 cycle, robot seed000: the box to "
            "(-0.3, -0.55)",
            4,
        ),
        Golden(
            "seed001_seed001",
            TwinConfig(profile=PROFILES["seed001"]),
            "seed001",
            {"cycles": 1},
            "task seed001 (report 001's Lua loop, its Heron IK as written), 1 cycle, "
            "robot seed001: the miss",
            4,
        ),
        Golden(
            "seed002_seed002",
            TwinConfig(profile=PROFILES["seed002"]),
            "seed002",
            {},
            "task seed002 (report 002's Lua, its Heron IK as written), robot seed002: the miss",
            4,
        ),
    ]
    out.append(
        Golden(
            "pick_place_break_mtb",
            heavy,
            "pick_place",
            {"cycles": 1},
            "pick_place, 1 cycle, robot mtb, a 0.5 kg box (4.9 N) on the stock finite-strength pad "
            "(max pull 3 N, shear 1 N, peel 0.1 N·m): the hold breaks",
        )
    )
    return out


@dataclass(frozen=True)
class Session:
    """A report's step-5 program (CLIENTS/<robot>.py) driving `twin serve --robot <robot>`."""

    name: str
    robot: str
    server_args: tuple[str, ...]
    how: str


def sessions() -> list[Session]:
    return [
        Session(
            "session_seed000",
            "seed000",
            (),
            "report 000's step-5 program against `twin serve --robot seed000` "
            "(realtime, speed 1): the box to (-0.3, -0.55) and back",
        ),
        Session(
            "session_seed001",
            "seed001",
            (),
            "report 001's step-5 program, robot seed001: its Heron IK misses the box by 13 cm",
        ),
        Session(
            "session_seed002",
            "seed002",
            (),
            "report 002's step-5 program, robot seed002: it stops at its "
            "first move (NameError joint1, as published)",
        ),
        Session(
            "session_seed003",
            "seed003",
            ("--start",),
            "report 003's step-5 program, robot seed003 (Play "
            "pressed, as its author did): the pad follows the link, the box stays",
        ),
    ]


def make_session(session: Session, out_dir: Path = RECORDINGS) -> Path:
    """Serve, run the program to its end, stop the run (which finalizes the recording), stop
    serving."""
    from coppeliasim_zmqremoteapi_client import RemoteAPIClient

    path = out_dir / f"{session.name}.mcap"
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--realtime",
            "--speed",
            "1",
            "--robot",
            session.robot,
            "--record",
            str(path),
            "--force",  # remaking a golden replaces it
            *session.server_args,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    try:
        port = int(
            re.search(
                r"listening on tcp://127\.0\.0\.1:(\d+)", _line(server, "listening on")
            ).group(1)
        )
        env = dict(os.environ, TWIN_REMOTE_PORT=str(port), TWIN_REMOTE_HOST="127.0.0.1")
        subprocess.run(
            [sys.executable, f"{session.robot}.py"],
            cwd=CLIENTS,
            env=env,
            capture_output=True,
            # some programs end in their own NameError, as published
            timeout=120,
            check=False,
        )
        RemoteAPIClient("127.0.0.1", port).require("sim").stopSimulation()
        _line(server, "recorded ")
    finally:
        server.terminate()
        server.wait(timeout=30)
    return path


def _line(server: subprocess.Popen, text: str) -> str:
    last = ""
    for line in server.stdout:
        if text in line:
            return line
        last = line.strip() or last
    raise TwinError(f"twin serve ended before printing {text!r}; its last line: {last!r}")


def make(golden: Golden, out_dir: Path = RECORDINGS) -> Path:
    """Record one golden into out_dir/NAME.mcap."""
    if isinstance(golden, Session):
        return make_session(golden, out_dir)
    path = out_dir / f"{golden.name}.mcap"
    run = {"source": "task", "task": golden.task, "params": golden.params}
    with open_recorders(
        golden.config, run, mcap_path=path, rate=golden.rate, engine=engine_versions()
    ) as sinks:
        record_task(golden.config, golden.task, golden.params, sinks=sinks)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help="goldens to remake (default: all)")
    parser.add_argument("--list", action="store_true", help="list the goldens and how each is made")
    parser.add_argument(
        "--out", default=str(RECORDINGS), help="output folder (default recordings/)"
    )
    args = parser.parse_args(argv)
    known = {g.name: g for g in [*goldens(), *sessions()]}
    unknown = [n for n in args.names if n not in known]
    if unknown:
        print(
            f"regen_goldens: error: unknown golden {unknown[0]!r}; expected one of "
            f"{', '.join(known)}",
            file=sys.stderr,
        )
        return 2
    chosen = [known[n] for n in args.names] if args.names else list(known.values())
    if args.list:
        for g in chosen:
            print(f"{g.name}.mcap: {g.how}")
        return 0
    try:
        for g in chosen:
            path = make(g, Path(args.out))
            print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")
    except TwinError as err:
        print(f"regen_goldens: error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
