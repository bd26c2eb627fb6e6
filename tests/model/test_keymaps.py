"""Key maps: the seeds' bindings act as the reports describe, user files are checked entry by
entry."""

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError
from twin.model.keymaps import BUILTIN, help_lines, keymap_for, load_keymap, parse_keys, quit_keys
from twin.model.profiles import PROFILES
from twin.sim.twin import Twin
from twin.sim.world import decode_key_events, pb

DEG = math.radians(1)


def _targets_after(profile: str, keys: list[str]) -> tuple[float, ...]:
    p = PROFILES[profile]
    twin = Twin(TwinConfig(profile=p, keymap=keymap_for(p)))
    try:
        for key in keys:
            twin.press_key(key)
        twin.step()
        return tuple(twin.targets), twin.signals.get(p.suction_signals[0])
    finally:
        twin.close()


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_every_builtin_map_is_valid_and_described(name):
    keymap = keymap_for(PROFILES[name])
    assert keymap and list(keymap) == sorted(keymap)
    lines = help_lines(keymap)
    assert len(lines) == len(keymap) and all(line.strip() for line in lines)


def _positions_after(profile: str, keys: list[str]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(joint positions right after the keys, without stepping; targets)."""
    p = PROFILES[profile]
    twin = Twin(TwinConfig(profile=p, keymap=keymap_for(p)))
    try:
        for key in keys:
            twin.press_key(key)
        return tuple(twin.frame.joint_q), tuple(twin.targets)
    finally:
        twin.close()


def test_seed000_keys_do_what_report_000_s_lua_does():
    """Its sysCall_actuation: angle1/angle2/d from 0, joints set at once (sim.setJointPosition)."""
    q, t = _positions_after("seed000", ["d", "d", "a"])
    # a jump, no motion
    assert q[0] == pytest.approx(DEG) and t[0] == pytest.approx(DEG) and q[1] == 0.0
    q, _ = _positions_after("seed000", ["e", "q", "q"])
    assert q[1] == pytest.approx(-DEG) and q[0] == 0.0
    q, _ = _positions_after("seed000", ["5"])
    assert q[2] == pytest.approx(0.084)  # its lower stop
    q, _ = _positions_after("seed000", ["5", "8"])  # d = d - 0.05 from 0: -0.05, wherever Z was
    assert q[2] == pytest.approx(-0.05)
    q, _ = _positions_after("seed000", ["8", "5", "8"])
    assert q[2] == pytest.approx(-0.10)
    t, suction = _targets_after("seed000", ["8"])
    assert suction == 1
    _, suction = _targets_after("seed000", ["8", "s"])
    assert suction == 0


def test_seed001_arrows_do_what_report_001_s_lua_does():
    """deg3 = deg2 - deg1 after left/right, deg1 - deg2 after up/down: the pad does not keep its
    heading."""
    t, _ = _targets_after("seed001", ["left", "left", "up"])
    shoulder, elbow, _z, wrist = t
    assert (shoulder, elbow, wrist) == pytest.approx((2 * DEG, DEG, DEG))  # deg3 = deg1 - deg2
    t, _ = _targets_after("seed001", ["up", "right"])
    assert (t[0], t[1], t[3]) == pytest.approx((-DEG, DEG, 2 * DEG))  # deg3 = deg2 - deg1
    t, suction = _targets_after("seed001", ["3"])
    assert t[2] == -0.055 and suction == 1
    t, suction = _targets_after("seed001", ["3", "4", "5"])
    assert t[2] == 0.0 and suction == 0


@pytest.mark.parametrize("name", ["mtb", "seed002", "seed003"])
def test_mtb_map_lowers_and_raises_in_each_scene_s_own_z(name):
    t, _ = _targets_after(name, ["k"])
    assert t[2] == PROFILES[name].z_down()
    t, _ = _targets_after(name, ["k", "i"])
    assert t[2] == PROFILES[name].z_up()


def test_seed000_keys_take_hold_when_the_stop_sets_the_pad_into_the_box():
    """Report 000's keys as its Lua does them: 5 sets joint3 to its stop (0.084, 2.4 cm below the
    loop's 0.06 on the box: the pad's sensor starts inside the box) and 8 switches suction on with a
    lift. With suction on up high, 5 takes hold (the sensor sees the box it starts in, as
    CoppeliaSim's does) and 8 lifts the box; 5 before 8 leaves the box where it is (suction comes on
    only as the pad lifts)."""
    p = PROFILES["seed000"]
    for keys, held in (("d*47 q*126 8 5 8", 0), ("d*47 q*126 5 8", -1)):
        twin = Twin(TwinConfig(profile=p, keymap=keymap_for(p)))
        try:
            for key in parse_keys(keys):
                twin.press_key(key)
                twin.wait(0.1)
            assert twin.suction_pad.held == held, keys
            box = twin.object_pose("box")
            assert math.dist(box[:2], (0.2, 0.7)) < 0.002
            # lifted with the pad, or left
            assert (box[2] > 0.1) if held == 0 else abs(box[2] - 0.025) < 1e-3
        finally:
            twin.close()


def test_quit_keys_never_steal_a_bound_key():
    assert "q" not in quit_keys(BUILTIN["seed000"])  # q is the elbow there
    assert quit_keys(BUILTIN["mtb"])[0] == "q"
    for keymap in BUILTIN.values():
        assert {"esc", "ctrl-c", "ctrl-d"} <= set(quit_keys(keymap))
        assert not set(keymap) & {"esc", "ctrl-c", "ctrl-d"}


def test_parse_keys_tokens_and_repeats():
    assert parse_keys("d*3 up  x * **2 wait*2 esc") == [
        "d",
        "d",
        "d",
        "up",
        "x",
        "*",
        "*",
        "*",
        "wait",
        "wait",
        "esc",
    ]
    assert parse_keys("") == []
    for bad, shown in (
        ("dd", "'dd'"),
        ("up*0", "*1 to *100000"),
        ("d*100001", "*1 to *100000"),
        ("Up", "'Up'"),
    ):
        with pytest.raises(ConfigError, match=r".*" + shown.replace("*", r"\*")):
            parse_keys(bad)


def test_user_keymap_toml_with_degrees_and_extends(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        'extends = "seed000"\n[keys]\nw = [["jog", "elbow", "2.5deg"]]\n'
        'x = [["target", "MTB_axis3", 0.1], ["signal", "lamp", 3]]\nd = ["jog", "shoulder", 0.1]\n'
    )
    keymap = load_keymap(path, PROFILES["mtb"])
    assert keymap["w"] == [["jog", "elbow", math.radians(2.5)]]
    assert keymap["x"] == [["target", "z", 0.1], ["signal", "lamp", 3]]
    assert keymap["d"] == [["jog", "shoulder", 0.1]]  # a single action without the outer list
    assert keymap["a"] == [["add", "shoulder", -DEG, "position"]]  # from seed000


def test_user_keymap_json(tmp_path):
    path = tmp_path / "mine.json"
    path.write_text(
        json.dumps({"keys": {"space": [["suction", 1]], "left": [["jog_keep_heading", "AB", 0.2]]}})
    )
    assert load_keymap(path, PROFILES["seed002"]) == {
        "left": [["jog_keep_heading", "shoulder", 0.2]],
        "space": [["suction", 1]],
    }


BAD_ENTRIES = [
    ('[keys]\nk = [["jog", "knee", 1]]', "unknown joint 'knee'"),
    ('[keys]\nk = [["spin", "elbow", 1]]', "op one of jog"),
    ('[keys]\nk = [["jog", "elbow"]]', "has 2 items"),
    ('[keys]\nk = [["jog", "elbow", "fast"]]', "value 'fast' is not a finite number"),
    ('[keys]\nk = [["jog", "z", "5deg"]]', "expected metres"),
    ('[keys]\nk = [["jog_keep_heading", "z", 0.01]]', "shoulder or elbow"),
    ('[keys]\nk = [["suction", 2]]', "suction value 2"),
    ('[keys]\nk = [["signal", "lamp", 1.5]]', "signal value 1.5"),
    ('[keys]\nesc = [["suction", 1]]', "key 'esc' is not a key name"),
    ("[keys]\nk = []", "non-empty list of actions"),
    ('[keys]\nk = [["jog", "elbow", 1]', "cannot be read"),
    ("keys = 3", "expected a table `keys`"),
    ('extends = "robot9"\n[keys]\nk = [["suction", 1]]', "extends 'robot9' is unknown"),
    ('colour = 1\n[keys]\nk = [["suction", 1]]', "unknown entries ['colour']"),
]


@pytest.mark.parametrize(("text", "message"), BAD_ENTRIES)
def test_bad_keymap_entry_is_one_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_keymap(path, PROFILES["mtb"])
    assert message in str(err.value) and "bad.toml" in str(err.value) and "\n" not in str(err.value)


def test_bad_keymap_file_on_the_command_line_exits_2_and_records_nothing(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[keys]\nk = [["jog", "knee", 1]]\n')
    rec = tmp_path / "run.mcap"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "teleop",
            "--keymap",
            str(path),
            "--keys",
            "k",
            "--record",
            str(rec),
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert (
        out.stderr.count("\n") == 1
        and "unknown joint 'knee'" in out.stderr
        and "Traceback" not in out.stderr
    )
    assert not rec.exists()
    missing = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "teleop",
            "--keymap",
            str(tmp_path / "no.toml"),
            "--keys",
            "k",
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert missing.returncode == 2 and "does not exist" in missing.stderr


def test_window_key_events_count_each_press_once():
    down: set[int] = set()
    a, trig, rel, is_down = ord("a"), pb.KEY_WAS_TRIGGERED, pb.KEY_WAS_RELEASED, pb.KEY_IS_DOWN
    assert decode_key_events({a: trig | is_down}, down) == ["a"]
    assert decode_key_events({a: is_down}, down) == []  # held
    assert decode_key_events({a: rel}, down) == []  # its release is not a second press
    assert decode_key_events({a: rel}, down) == ["a"]  # a quick tap seen only as released
    assert decode_key_events({a: trig | rel}, down) == ["a"]
    assert decode_key_events(
        {pb.B3G_LEFT_ARROW: trig, pb.B3G_SHIFT: is_down, ord("d"): trig}, down
    ) == ["D", "left"]
    assert decode_key_events({27: trig, pb.B3G_F1 + 1: trig, 7: trig}, down) == ["esc", "f2"]


def test_readme_example_keymap_loads(tmp_path):
    readme = (Path(__file__).resolve().parents[2] / "docs/how-to/teleop.md").read_text()
    path = tmp_path / "example.toml"
    path.write_text(re.search(r"```toml\n(.*?)```", readme, re.DOTALL).group(1))
    keymap = load_keymap(path, PROFILES["mtb"])
    assert keymap["w"] == [["jog", "elbow", math.radians(2)]] and keymap["n"] == [
        ["signal", "lamp", 1]
    ]
    assert keymap["left"] == [["jog_keep_heading", "shoulder", math.radians(1)]] and "g" in keymap
