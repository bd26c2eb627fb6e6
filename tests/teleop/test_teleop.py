"""Scripted teleop (--keys): a pick and a place on the seeds' 1-degree key grid, recorded and
replayed exactly; unknown keys, joint limits and bad options."""

import math
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.teleop_plan import MAPS, plan

from twin.cli import main
from twin.model.errors import ConfigError
from twin.model.keymaps import parse_keys
from twin.model.profiles import PROFILES
from twin.record.mcap.reader import load
from twin.sim.twin import Twin
from twin.tasks.pick_place import POINT_B_M
from twin.teleop.screen import status_lines
from twin.teleop.session import (
    EventLog,
    Session,
    TeleopOptions,
    run_teleop,
    summary_lines,
    teleop_config,
)
from twin.verify.collectors import FrameCollector
from twin.verify.replay import REPLAYED_EVENT_KINDS, collected, replay

KEY_INTERVAL_S = 0.1
STEPS_PER_KEY = 24  # 0.1 s at 240 Hz


def key_script(profile_name, pick, place):
    up1, down1, up2, down2 = MAPS[profile_name]["jog"]

    def moves(frm, to):
        d1, d2 = to[0] - frm[0], to[1] - frm[1]
        return [up1 if d1 > 0 else down1] * abs(d1) + [up2 if d2 > 0 else down2] * abs(d2)

    keys = (
        moves((0, 0), pick)
        + MAPS[profile_name]["pick"]
        + moves(pick, place)
        + MAPS[profile_name]["place"]
    )
    return " ".join(keys)


def _scripted(robot, keys, interval_s=0.5, record=None):
    collector = FrameCollector()
    opts = TeleopOptions(
        robot=robot,
        keys=keys,
        key_interval_s=interval_s,
        record_path=record,
        extra_sinks=[collector],
    )
    session = run_teleop(opts)
    return session, collected(collector, teleop_config(opts), {"source": "teleop"})


def _assert_replays_exactly(rec):
    again = replay(rec)
    assert again.frames.equals(rec.frames)
    assert again.commands == rec.commands

    def kinds(events):
        return [
            (e.step, e.kind, e.body, e.message) for e in events if e.kind in REPLAYED_EVENT_KINDS
        ]

    assert kinds(again.events) == kinds(rec.events)


@pytest.mark.parametrize("robot", sorted(MAPS))
def test_scripted_pick_and_place_on_the_key_grid_replays_exactly(robot, tmp_path, capsys):
    pick, place, predicted_m = plan(robot)
    grid_error_m = math.dist(predicted_m, POINT_B_M)
    assert grid_error_m < 0.005  # what the 1-degree grid allows for this robot
    path = tmp_path / f"teleop_{robot}.mcap"
    script = key_script(robot, pick, place)
    session, rec = _scripted(robot, script, interval_s=KEY_INTERVAL_S, record=str(path))
    kinds = [e.kind for e in rec.events]
    assert kinds.count("attach") == 1 and kinds.count("release") == 1 and "key_unknown" not in kinds
    box = session.twin.frame.object_poses[0]
    # The box lands where the grid puts it (within 2 mm of the prediction: suction sensing and the
    # drop) and within 5 mm of the place point.
    assert math.dist(box[:2], predicted_m) < 0.002
    assert math.dist(box[:2], POINT_B_M) < 0.005
    assert abs(box[2] - 0.025) < 1e-3 and rec.frames.held_body[-1] == -1
    # every key press is one "key" Command stamped with the step it took effect at, one interval
    # apart
    tokens = script.split()
    keys = [c for c in rec.commands if c.kind == "key"]
    assert [c.args["key"] for c in keys] == [t for t in tokens if t != "wait"]
    assert [c.step for c in keys] == [
        STEPS_PER_KEY * i for i, t in enumerate(tokens) if t != "wait"
    ]
    # the interval runs once more after the last key
    assert len(rec.frames) == STEPS_PER_KEY * len(tokens) + 1
    # the file holds the session (config with the key map, every frame and command) and `twin
    # replay` matches it
    loaded = load(path)
    assert (
        loaded.finalized
        and loaded.run["source"] == "teleop"
        and loaded.config.keymap == rec.config.keymap
    )
    assert loaded.frames.equals(rec.frames) and loaded.commands == rec.commands
    assert main(["replay", str(path)]) == 0
    assert capsys.readouterr().out.startswith("MATCH")


def test_unknown_key_is_ignored_shown_and_replayed():
    session, rec = _scripted("seed001", "left z 3")
    unknown = [e for e in rec.events if e.kind == "key_unknown"]
    assert len(unknown) == 1 and unknown[0].step == 120 and unknown[0].data == {"key": "z"}
    # nothing moved for z
    assert rec.frames.joint_target[240].tolist() == rec.frames.joint_target[239].tolist()
    screen = "\n".join(status_lines(session))
    assert (
        "last keys left z(unknown) 3" in screen
        and "key_unknown" in screen
        and "'z' is not in the key map" in screen
    )
    assert "1 not in the key map" in summary_lines(session)[0]
    _assert_replays_exactly(rec)


def test_joint_driven_past_its_limit_stops_there_with_an_event():
    # mtb's shoulder has limits (the seeds' CoppeliaSim joints are cyclic and have none)
    limit_deg = math.degrees(PROFILES["mtb"].shoulder_limit_rad)
    presses = int(limit_deg) + 5
    session, rec = _scripted("mtb", f"D*{presses}", interval_s=0.05)
    limits = [e for e in rec.events if e.kind == "joint_limit"]
    assert len(limits) == presses - int(limit_deg)
    assert all(
        e.data["joint"] == "MTB_axis1" and e.data["limit"] == pytest.approx(math.radians(limit_deg))
        for e in limits
    )
    q = session.twin.frame.joint_q
    assert math.degrees(q[0]) == pytest.approx(limit_deg, abs=0.05)
    # the wrist stopped turning with the shoulder, so the pad kept its heading
    assert session.twin.targets[3] == pytest.approx(-PROFILES["mtb"].shoulder_limit_rad)
    assert math.degrees(q[0] + q[1] + q[3]) == pytest.approx(0.0, abs=0.05)
    _assert_replays_exactly(rec)


def test_quit_key_in_a_script_ends_the_session_there():
    session, rec = _scripted("mtb", "d q d", interval_s=0.1)
    assert [p.key for p in session.presses] == ["d"] and session.ended_by == "q"
    assert len(rec.frames) == 25
    session, _ = _scripted("seed000", "q esc e", interval_s=0.1)  # q is seed000's elbow; Esc quits
    assert [p.key for p in session.presses] == ["q"] and session.ended_by == "esc"


def _cli(*args, env=None, timeout=60):
    return subprocess.run(
        [sys.executable, "-m", "twin.cli", "teleop", *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        stdin=subprocess.DEVNULL,
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--keys", "d dd"], "--keys token 'dd' is not a key"),
        (["--keys", "d", "--key-interval", "0"], "--key-interval 0.0 s is invalid"),
        (["--keys", "d", "--key-interval", "nan"], "--key-interval nan s is invalid"),
        (["--keys", "d", "--robot", "seed9"], "unknown robot 'seed9'"),
        (["--keys", "d", "--record", "x.txt"], "should end in .mcap"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(args, message, capsys):
    assert main(["teleop", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and err.startswith("twin: error: ")


def test_the_screen_without_a_terminal_is_one_line_and_exit_2():
    out = _cli()  # stdin is not a terminal
    assert out.returncode == 2 and "the teleop screen needs a terminal" in out.stderr
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr


def test_cli_scripted_session_prints_a_summary():
    out = _cli("--robot", "seed000", "--keys", "d*2 e 5 8 s", "--key-interval", "0.2")
    assert out.returncode == 0, out.stderr
    assert (
        "teleop (scripted) robot seed000: 6 key presses (0 not in the key map), 288 steps"
        in out.stdout
    )
    assert "box final pose" in out.stdout


def test_teleop_config_carries_the_keymap():
    config = teleop_config(TeleopOptions(robot="seed001"))
    assert set(config.keymap) == {"left", "right", "up", "down", "3", "4", "5"}
    with pytest.raises(ConfigError):
        teleop_config(TeleopOptions(robot="seed001", keymap_path="/nonexistent/map.toml"))


def test_paced_script_runs_in_real_time_with_the_same_commands():
    """With a window (--gui) a script is paced to wall-clock time; the Commands and Frames are the
    same."""
    _, fast = _scripted("mtb", "d k wait", interval_s=0.1)
    config = teleop_config(TeleopOptions(robot="mtb"))
    collector = FrameCollector()
    twin = Twin(config, sinks=[collector])
    session = Session(twin, EventLog())
    start_s = time.monotonic()
    session.run_scripted(parse_keys("d k wait"), 0.1, pace=session.real_time_pacer())
    wall_s = time.monotonic() - start_s
    twin.close()
    # 72 steps of 1/240 s; the pacer sleeps only when over 2 ms ahead, so it may end 2 ms early
    assert 0.3 - 0.002 <= wall_s < 1.5
    assert collector.commands == fast.commands and collector.columns().equals(fast.frames)


def test_report_000s_own_keys_from_the_readme_pick_and_place_the_box(tmp_path):
    readme = (Path(__file__).resolve().parents[2] / "docs/how-to/teleop.md").read_text()
    line = next(
        x for x in readme.splitlines() if x.startswith("twin teleop --robot seed000 --keys")
    )
    keys = line.split('"')[1]
    out = _cli("--robot", "seed000", "--keys", keys, "--record", str(tmp_path / "keys000.mcap"))
    assert out.returncode == 0, out.stderr
    rec = load(tmp_path / "keys000.mcap")
    kinds = [e.kind for e in rec.events]
    assert kinds.count("attach") == 1 and kinds.count("release") == 1
    box = rec.frames.object_poses[-1][0]
    assert math.dist(box[:2], POINT_B_M) < 0.005 and abs(box[2] - 0.025) < 1e-3


@pytest.mark.parametrize("robot", ["seed001", "seed000"])
def test_a_keys_run_prints_how_far_the_box_ended_from_the_place_point_as_the_readme_says(robot):
    readme = (Path(__file__).resolve().parents[2] / "docs/how-to/teleop.md").read_text()
    keys = next(
        x for x in readme.splitlines() if x.startswith(f"twin teleop --robot {robot} --keys")
    ).split('"')[1]
    # the README's figure for it
    said = re.search(rf"{robot}'s .*?(\d+\.\d) mm", readme, re.DOTALL).group(1)
    out = _cli("--robot", robot, "--keys", keys)
    assert out.returncode == 0, out.stderr
    assert f", {said} mm from the place point (-0.3, -0.55) in x and y" in out.stdout
