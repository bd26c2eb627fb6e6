"""`twin export --format ros2`: a rosbag2 bag that rosbags reads back with the recording's values,
that Foxglove's mcap-ros2-support (a second, independent CDR reader) decodes message by message,
laid out as rosbag2 writes it (profile ros2, a ros2msg schema on every channel, metadata.yaml v9
with each topic's QoS), byte-identical when exported again."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from support.cli import twin

import twin as twin_pkg
from twin.model.joint_log import JointLog
from twin.ros2.messages import TYPESTORE

TYPES = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/joint_targets": "sensor_msgs/msg/JointState",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/robot_description": "std_msgs/msg/String",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/suction/on": "std_msgs/msg/Bool",
    "/suction/held": "std_msgs/msg/String",
    "/events": "rcl_interfaces/msg/Log",
}


@pytest.fixture(scope="module")
def exported(pick_place_cli, tmp_path_factory):
    """The 1-cycle pick_place run exported by the command: (recording, bag folder)."""
    bag = tmp_path_factory.mktemp("ros2") / "bag"
    from twin.cli import main

    assert main(["export", str(pick_place_cli["mcap"]), "--format", "ros2", "-o", str(bag)]) == 0
    return twin_pkg.load(pick_place_cli["mcap"]), bag


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_rosbags_reads_every_topic_with_the_recordings_values(exported):
    rec, bag = exported
    frames = rec.frames
    got: dict[str, list] = {}
    with Reader(bag) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TYPES
        for conn, log_ns, data in reader.messages():
            msg = TYPESTORE.deserialize_cdr(data, conn.msgtype)
            got.setdefault(conn.topic, []).append((log_ns, msg))
    states = got["/joint_states"]
    assert len(states) == len(frames)  # one a recorded frame
    assert [t for t, _ in states] == [_ns(m.header.stamp) for _, m in states] == list(frames.t_ns)
    assert list(states[0][1].name) == list(rec.config.profile.joint_names)
    for key, column in (
        ("position", "joint_q"),
        ("velocity", "joint_qd"),
        ("effort", "joint_effort"),
    ):
        values = np.array([getattr(m, key) for _, m in states])
        assert values.tobytes() == getattr(frames, column).tobytes(), key  # bit-equal
    targets = np.array([m.position for _, m in got["/joint_targets"]])
    assert targets.tobytes() == frames.joint_target.tobytes()
    assert [_ns(m.clock) for _, m in got["/clock"]] == list(frames.t_ns)
    assert [m.data for _, m in got["/suction/on"]] == list(frames.suction_on)
    held = [m.data for _, m in got["/suction/held"]]
    assert held.count("box") == int(np.sum(frames.held_body == 0)) > 100
    assert got["/robot_description"][0][1].data == rec.urdf
    pads = [t for _, m in got["/tf"] for t in m.transforms if t.child_frame_id == "pad_tip"]
    pad = np.array([(t.transform.translation.x, t.transform.translation.y) for t in pads])
    assert np.array_equal(pad, frames.pad_pose[:, :2])
    boxes = [t for _, m in got["/tf"] for t in m.transforms if t.child_frame_id == "box"]
    assert [b.transform.rotation.w for b in boxes] == list(frames.object_poses[:, 0, 6])
    events = [json.loads(m.msg) for _, m in got["/events"]]
    assert [(e["kind"], e["message"]) for e in events] == [(e.kind, e.message) for e in rec.events]
    (static,) = [m for _, m in got["/tf_static"]]
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ("world", "MTB_base")
    ]


def test_a_second_reader_decodes_every_message(exported):
    rec, bag = exported
    (mcap_file,) = bag.glob("*.mcap")
    counts: Counter = Counter()
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        for _, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            if channel.topic == "/joint_states":
                i = counts[channel.topic] - 1
                assert tuple(decoded.position) == tuple(rec.frames.joint_q[i])
                assert decoded.header.stamp.nanosec == rec.frames.t_ns[i] % 1_000_000_000
            assert message.log_time == message.publish_time
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert sum(counts.values()) == meta["message_count"] == summary.statistics.message_count
    assert counts["/joint_states"] == len(rec.frames) and counts["/events"] == len(rec.events)


def test_metadata_is_rosbag2s_with_each_topics_qos(exported):
    _, bag = exported
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["bag.mcap"] and (bag / "bag.mcap").is_file()
    assert meta["starting_time"]["nanoseconds_since_epoch"] == 0  # simulated time
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert set(topics) == set(TYPES)
    for name, topic in topics.items():
        info = topic["topic_metadata"]
        assert info["type"] == TYPES[name] and info["serialization_format"] == "cdr"
        assert info["type_description_hash"].startswith("RIHS01_")
        (qos,) = info["offered_qos_profiles"]
        latched = name in ("/robot_description", "/tf_static")
        assert qos["durability"] == ("transient_local" if latched else "volatile"), name
        assert qos["reliability"] == "reliable"


def test_a_second_export_is_byte_identical_and_loads_as_a_joint_log(exported, tmp_path, capsys):
    rec, bag = exported
    again = tmp_path / "bag"  # the same name: the MCAP file is named after its folder
    code, out, _ = twin(capsys, "export", rec.path, "--format", "ros2", "-o", again)
    assert code == 0 and f"wrote {again}: ROS 2 bag" in out
    for name in ("bag.mcap", "metadata.yaml"):
        assert (again / name).read_bytes() == (bag / name).read_bytes(), name
    for source in (bag, bag / "bag.mcap"):  # the folder, or its MCAP file alone
        log = twin_pkg.load(source)
        assert (
            isinstance(log, JointLog) and log.position_rad.tobytes() == rec.frames.joint_q.tobytes()
        )
        assert set(log.tf) == {"MTB_base", "pad_tip", "box"}


def test_an_existing_bag_is_replaced_only_with_force(exported, tmp_path, capsys):
    rec, bag = exported
    target = tmp_path / "b"
    shutil.copytree(bag, target)
    (target / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    code, _, err = twin(capsys, "export", rec.path, "--format", "ros2", "-o", target)
    assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1
    assert (target / "metadata.yaml").read_text() == "rosbag2_bagfile_information: {}\n"
    assert twin(capsys, "export", rec.path, "--format", "ros2", "-o", target, "--force")[0] == 0
    assert sorted(p.name for p in target.iterdir()) == ["b.mcap", "metadata.yaml"]
    assert [p.name for p in tmp_path.iterdir()] == ["b"]  # no temporary left beside it
    other = tmp_path / "notes"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    code, _, err = twin(capsys, "export", rec.path, "--format", "ros2", "-o", other, "--force")
    assert code == 2 and "no ROS 2 bag" in err and (other / "keep.txt").read_text() == "mine"


def test_several_recordings_one_bag_each(exported, camera_run, tmp_path, capsys):
    rec, _ = exported
    out = tmp_path / "bags"
    code, printed, err = twin(
        capsys, "export", rec.path, camera_run["mcap"], "--format", "ros2", "-o", out
    )
    assert code == 0, err
    stems = sorted([Path(rec.path).stem, Path(camera_run["mcap"]).stem])
    assert sorted(p.name for p in out.iterdir()) == stems
    assert printed.count("ROS 2 bag") == 2
    cam = twin_pkg.load(camera_run["mcap"])
    with Reader(out / Path(camera_run["mcap"]).stem) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        for name, track in cam.cameras.items():
            image_topic, info_topic = (
                f"/camera/{name}/image/compressed",
                f"/camera/{name}/camera_info",
            )
            assert topics[image_topic] == "sensor_msgs/msg/CompressedImage"
            assert topics[info_topic] == "sensor_msgs/msg/CameraInfo"
            images = [
                TYPESTORE.deserialize_cdr(d, c.msgtype)
                for c, _, d in reader.messages(
                    [c for c in reader.connections if c.topic == image_topic]
                )
            ]
            assert [bytes(m.data) for m in images] == track.data
            assert {m.format for m in images} == {track.format}
            (info_conn,) = [c for c in reader.connections if c.topic == info_topic]
            _, _, data = next(reader.messages([info_conn]))
            info = TYPESTORE.deserialize_cdr(data, info_conn.msgtype)
            assert (info.width, info.height) == (track.width_px, track.height_px)
            assert info.k[2] == track.width_px / 2


def test_a_bag_is_not_exported_again(exported, tmp_path, capsys):
    _, bag = exported
    code, _, err = twin(
        capsys, "export", bag / "bag.mcap", "--format", "ros2", "-o", tmp_path / "b"
    )
    assert code == 2 and "is a ROS 2 bag already" in err and not (tmp_path / "b").exists()


@pytest.mark.parametrize("command", ["info", "replay", "check"])
def test_twins_own_commands_say_a_bag_is_one(exported, capsys, command):
    _, bag = exported
    for target in (bag, bag / "bag.mcap"):
        code, out, err = twin(capsys, command, target)
        assert code == 2 and "ROS 2 bag" in (err + out) and "twin diff and twin.load" in err + out
