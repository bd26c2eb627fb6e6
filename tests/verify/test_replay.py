"""`twin replay`: rebuild from the recording's metadata alone, feed its Commands back, compare."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from support.cli import twin
from support.runs import record_pick_place

from twin.cli import main
from twin.compare.engine import compare
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.keymaps import builtin_keymap
from twin.model.types import Command
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.sim.twin import Twin
from twin.verify.collectors import FrameCollector
from twin.verify.replay import REPLAYED_EVENT_KINDS, collected, replay, save


def record_teleop(path) -> None:
    """A keyboard session: mtb's key map, a key every 0.25 s, one key the map does not know."""
    config = TwinConfig(keymap=builtin_keymap("mtb"))
    run = {"source": "teleop", "task": "", "params": {"keys": "d d d l l k g i x r"}}
    with open_recorders(config, run, mcap_path=path) as sinks:
        t = Twin(config, sinks=sinks)
        for key in run["params"]["keys"].split():
            t.press_key(key)
            t.step(60)
        t.close()


def record_remote(path) -> None:
    """What a remote client sends: kinematic sets, motor targets, speed limits and signals."""
    config = TwinConfig()
    run = {"source": "remote", "task": "", "params": {"port": 23000}}
    with open_recorders(config, run, mcap_path=path) as sinks:
        t = Twin(config, sinks=sinks)
        t.set_joint_position("MTB_axis1", 0.3)
        t.step(10)
        t.set_joint_max_velocity("MTB_axis2", 1.0)
        t.set_joint_target("MTB_axis2", 0.8)
        t.set_joint_target("MTB_axis3", 0.5)  # beyond the Z stroke: a joint_limit event
        t.step(200)
        t.set_signal("pad_switch", 1)
        t.step(50)
        t.set_signal("pad_switch", None)
        t.step(30)
        t.close()


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    d = tmp_path_factory.mktemp("replay")
    record_pick_place(d / "task.mcap", rate=3)
    record_teleop(d / "teleop.mcap")
    record_remote(d / "remote.mcap")
    return d


@pytest.mark.parametrize("kind", ["task", "teleop", "remote"])
def test_replay_matches_exactly_for_every_source(recs, capsys, tmp_path, kind):
    code, out, err = twin(
        capsys, "replay", recs / f"{kind}.mcap", "--record", tmp_path / "new.mcap"
    )
    assert (code, err) == (0, ""), out
    # the default, on one machine
    assert out.startswith("MATCH (tolerance noise") and "  bit-identical\n" in out
    original, new = load(recs / f"{kind}.mcap"), load(tmp_path / "new.mcap")
    # the replay's run is the original's, and says which file it replays
    assert new.run == {
        **original.run,
        "replay_of": {"file": f"{kind}.mcap", "sha256": new.run["replay_of"]["sha256"]},
    }
    assert new.config == original.config
    assert [(c.step, c.kind, c.args) for c in new.commands] == [
        (c.step, c.kind, c.args) for c in original.commands
    ]
    assert new.frames.step[-1] == original.frames.step[-1]


def test_replayed_events_are_the_twins_own(recs):
    teleop = load(recs / "teleop.mcap")
    assert any(e.kind == "key_unknown" for e in teleop.events)
    result = compare(teleop, replay(teleop), event_kinds=REPLAYED_EVENT_KINDS)
    assert result.match and result.events_matched == sum(
        e.kind in REPLAYED_EVENT_KINDS for e in teleop.events
    )
    remote = load(recs / "remote.mcap")
    assert any(e.kind == "joint_limit" for e in remote.events)


def test_replay_uses_the_recorded_commands(recs, capsys, tmp_path):
    rec = load(recs / "remote.mcap")
    changed = [
        dataclasses.replace(c, args={**c.args, "q": 0.81})
        if c.kind == "joint_target" and c.args["joint"] == "MTB_axis2"
        else c
        for c in rec.commands
    ]
    rec.commands = changed
    save(rec, tmp_path / "edited.mcap")
    code, _out, _ = twin(
        capsys, "replay", tmp_path / "edited.mcap", "--report", tmp_path / "r.json"
    )
    assert code == 1
    first = json.loads((tmp_path / "r.json").read_text())["first"]
    assert first["channel"] == "joints" and first["step"] == 11  # the target changed at step 10


def test_replay_needs_only_the_metadata(recs):
    rec = load(recs / "task.mcap")
    assert rec.config == TwinConfig() and len(rec.commands) > 0
    direct = FrameCollector()
    t = Twin(rec.config, sinks=[direct])
    for c in rec.commands:  # the same commands, fed by hand: the same run
        while t.step_index < c.step:
            t.step()
        t.apply(c)
    t.step(int(rec.frames.step[-1]) - t.step_index)
    t.close()
    assert compare(
        rec, collected(direct, rec.config, rec.run), event_kinds=REPLAYED_EVENT_KINDS
    ).match


def test_replay_refuses_a_command_after_the_last_frame(recs):
    rec = load(recs / "remote.mcap")
    rec.commands.append(
        Command(int(rec.frames.step[-1]) + 5, "signal", {"name": "pad_switch", "value": 1})
    )
    with pytest.raises(RecordingError, match="after its last frame"):
        replay(rec)


def test_replay_bad_input(capsys, tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\0" * 20)
    code, out, err = twin(capsys, "replay", tmp_path / "x.mcap")
    assert code == 2 and out == "" and err.startswith("twin: error: ") and err.count("\n") == 1
    code, _, err = twin(capsys, "replay", tmp_path / "missing.mcap")
    assert code == 2 and "does not exist" in err


def test_check_replays_a_golden_without_a_task(recs):
    from twin.compare.tolerances import Tolerances
    from twin.verify.check import check_all

    outcomes = check_all(
        [str(recs / "teleop.mcap"), str(recs / "remote.mcap")], Tolerances.from_preset("exact")
    )
    assert [o.status for o in outcomes] == ["match", "match"]


def test_replay_refuses_to_record_over_the_recording_it_replays(tmp_path, capsys):
    golden = tmp_path / "golden.mcap"
    golden.write_bytes(
        (Path(__file__).resolve().parents[2] / "recordings" / "pick_place_mtb.mcap").read_bytes()
    )
    before = golden.read_bytes()
    assert main(["replay", str(golden), "--record", str(golden)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "would overwrite its input" in err
    assert golden.read_bytes() == before


def test_a_user_robot_replays_from_the_recording_alone_after_its_files_are_gone(tmp_path, capsys):
    import shutil

    from support.user_robot import write_user_robot  # the STL-mesh SCARA the URDF tests build

    profile_file = write_user_robot(tmp_path / "robot")
    recording = tmp_path / "user.mcap"
    assert (
        main(
            [
                "run",
                "pick_place",
                "--cycles",
                "1",
                "--robot",
                str(profile_file),
                "--record",
                str(recording),
            ]
        )
        == 0
    )
    shutil.rmtree(tmp_path / "robot")  # the URDF and its STL meshes: replay must not need them
    capsys.readouterr()
    assert main(["replay", str(recording)]) == 0
    assert capsys.readouterr().out.startswith("MATCH")
