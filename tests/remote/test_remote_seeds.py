"""The reports' step-5 programs, as their authors wrote them, against `twin serve --realtime` at
speed 1.

tests/fixtures/seed_clients/ holds each report's Python program verbatim but for two lines: the
import (`from twin.remote import legacy as vrep` for `import sim as vrep`) and a bound on the
endless loop (`for _pass in range(1):` for `while True:`). The programs keep their own addresses
(the environment's TWIN_REMOTE_HOST points them at the server), their sleeps and their errors: 000's
and 003's loops are followed by a stray Lua `end` (NameError once the bounded loop ends), and 002's
IK sends to names it never defines (NameError at its first move). Each runs against its own server
on its own seed profile, whose joint conventions are its report's scene's
(docs/seed-conventions.md), all four at once; they take as long as their sleeps (11 s for the
longest).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from support.server import ServerProcess

from twin.cli import main as twin_main
from twin.record.mcap.reader import load

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

CLIENTS = Path(__file__).resolve().parents[1] / "fixtures" / "seed_clients"
A_M = (0.2, 0.7)
B_M = (-0.3, -0.55)
SEEDS = ("seed000", "seed001", "seed002", "seed003")


def run_seed(seed: str, folder: Path, *server_args: str):
    """Serve, run the seed's program to its end, read the box, stop the run: (recording, box,
    program)."""
    record = folder / f"{seed}.mcap"
    with ServerProcess(
        "--realtime", "--speed", "1", "--robot", seed, "--record", str(record), *server_args
    ) as server:
        env = dict(os.environ, TWIN_REMOTE_PORT=str(server.port), TWIN_REMOTE_HOST="127.0.0.1")
        program = subprocess.run(
            [sys.executable, f"{seed}.py"],
            cwd=CLIENTS,
            capture_output=True,
            text=True,
            env=env,
            timeout=90,
            check=False,
        )
        assert "Connected to remote API server" in program.stdout, program.stdout + program.stderr
        sim = server.client().require("sim")
        box = sim.getObjectPosition(sim.getObject("/box"), sim.handle_world)
        sim.stopSimulation()
        server.wait_for(rf"recorded .*{seed}\.mcap")
    return load(record), box, program


@pytest.fixture(scope="module")
def seed_runs(tmp_path_factory) -> dict:
    """All four programs at once (each with its own server): seed -> (recording, box, program,
    folder)."""
    folder = tmp_path_factory.mktemp("seeds")
    results: dict = {}

    def work(seed: str) -> None:
        try:  # report 003's author pressed Play: its program never starts the simulation
            results[seed] = (
                *run_seed(seed, folder, *(["--start"] if seed == "seed003" else [])),
                folder,
            )
        except BaseException as err:  # noqa: BLE001 - handed to the test that asks for this seed
            results[seed] = err

    threads = [threading.Thread(target=work, args=(seed,)) for seed in SEEDS]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=180)
    return results


def _result(seed_runs: dict, seed: str):
    result = seed_runs.get(seed)
    if result is None:
        raise AssertionError(f"{seed} did not finish")
    if isinstance(result, BaseException):
        raise result
    return result


def _box_xy(rec, step: int) -> tuple[float, float]:
    pose = rec.frames.object_poses[min(step, len(rec.frames) - 1)][0]
    return float(pose[0]), float(pose[1])


def _pad_xy(rec, step: int) -> tuple[float, float]:
    pose = rec.frames.pad_pose[min(step, len(rec.frames) - 1)]
    return float(pose[0]), float(pose[1])


def _kinds(rec, *kinds: str) -> list:
    return [e for e in rec.events if e.kind in kinds]


def _replays_exactly(path: str, capsys) -> None:
    capsys.readouterr()
    assert twin_main(["replay", path]) == 0
    assert "MATCH" in capsys.readouterr().out


def test_the_fixtures_are_the_reports_programs_but_for_the_import_and_the_loop_bound():
    seeds = Path(__file__).resolve().parents[3] / "shared" / "seeds"
    if not seeds.is_dir():
        pytest.skip("the reports are not beside this checkout")
    reports = {
        p.name[:3]: p.read_text(encoding="utf-8").replace("\u00a0", " ")
        for p in seeds.glob("*.txt")
    }
    for seed in SEEDS:
        changed = []
        for line in (CLIENTS / f"{seed}.py").read_text(encoding="utf-8").splitlines():
            if line.strip() and line not in reports[seed[-3:]]:
                changed.append(line.strip())
        assert changed[0] == "from twin.remote import legacy as vrep"
        assert all(
            c.startswith("for _pass in range(1):  # the report: while True") for c in changed[1:]
        ), changed


def test_report000_program_carries_the_box_to_b_and_back(seed_runs, capsys):
    rec, box, program, folder = _result(seed_runs, "seed000")
    # the stray Lua `end` after its loop
    assert "NameError: name 'end' is not defined" in program.stderr
    attaches, releases = _kinds(rec, "attach"), _kinds(rec, "release")
    assert len(attaches) == 2 and len(releases) == 2
    assert math.dist(_box_xy(rec, releases[0].step + 240), B_M) < 0.005  # placed at B
    assert math.dist(box[:2], A_M) < 0.005  # picked up again at B and placed back at A
    assert not _kinds(rec, "suction_empty", "joint_limit")
    _replays_exactly(str(folder / "seed000.mcap"), capsys)


@pytest.mark.parametrize("seed, miss_m", [("seed001", (0.10, 0.16))])
def test_report001_program_misses_the_box_and_the_recording_shows_it(
    seed, miss_m, seed_runs, capsys
):
    rec, box, program, folder = _result(seed_runs, seed)
    assert program.returncode == 0, program.stderr
    empty = _kinds(rec, "suction_empty")
    assert empty and all(e.message == "suction on, nothing sensed" for e in empty)
    assert not _kinds(rec, "attach")
    # the pick at A: lowered with suction on, the pad came no nearer the box than 13 cm
    lowered = [s for s in range(len(rec.frames)) if rec.frames.pad_pose[s][2] < 0.06]
    assert lowered
    miss = min(math.dist(_pad_xy(rec, s), _box_xy(rec, s)) for s in lowered)
    assert miss_m[0] < miss < miss_m[1], miss
    assert math.dist(box[:2], A_M) < 0.001
    _replays_exactly(str(folder / f"{seed}.mcap"), capsys)


def test_report002_program_stops_at_its_first_move_and_never_reaches_the_box(seed_runs, capsys):
    rec, box, program, folder = _result(seed_runs, "seed002")
    # its IK sends to joint1..joint3
    assert "NameError: name 'joint1' is not defined" in program.stderr
    assert not _kinds(rec, "attach")
    far = min(math.dist(_pad_xy(rec, s), A_M) for s in range(len(rec.frames)))
    assert far > 0.25  # the pad stayed at home, (0, 1.0), lowered there with suction on
    assert math.dist(box[:2], A_M) < 0.001
    _replays_exactly(str(folder / "seed002.mcap"), capsys)


def test_report003_pad_only_follows_the_link_and_the_box_stays(seed_runs, capsys):
    """Its author: the pad "cannot be put down, it only follows the link" (Z moves of +-1 mm)."""
    rec, box, program, folder = _result(seed_runs, "seed003")
    assert "NameError: name 'end' is not defined" in program.stderr
    assert not _kinds(rec, "attach")
    lowest_tip_m = float(min(p[2] for p in rec.frames.pad_pose))
    assert lowest_tip_m > rec.config.profile.tip_z0_m - 0.0021  # never more than 2 mm down
    # MTB_axis3 stops at 0
    assert [e.data["requested"] for e in _kinds(rec, "joint_limit")] == [-0.001, -0.001]
    assert math.dist(box[:2], A_M) < 0.001
    _replays_exactly(str(folder / "seed003.mcap"), capsys)
