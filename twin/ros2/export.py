"""A recording as a rosbag2 bag (MCAP storage, metadata.yaml version 9), written with rosbags.

Every message is stamped, and logged, at its frame's simulated time (the first frame at 0), so
`ros2 bag play --clock` plays the run in simulated time. Messages go in time order; at one time,
in TOPICS order. The same recording exported to a bag of the same name gives the same bytes.
"""

from __future__ import annotations

import os
import secrets
import shutil
from contextlib import suppress
from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer

from twin.model.errors import ConfigError
from twin.model.recording import Recording
from twin.record.mcap.scan import BAG_METADATA, is_bag_folder
from twin.record.mcap.scene_tf import PAD_TIP, SceneTransforms
from twin.record.outputs import fsync_file, publish
from twin.ros2 import messages as m

BAG_VERSION = 9  # rosbag2's metadata version since Jazzy

# topic -> (message type, latched: transient-local QoS); the order messages of one time go in
TOPICS: dict[str, tuple[str, bool]] = {
    "/robot_description": ("std_msgs/msg/String", True),
    "/tf_static": ("tf2_msgs/msg/TFMessage", True),
    "/clock": ("rosgraph_msgs/msg/Clock", False),
    "/joint_states": ("sensor_msgs/msg/JointState", False),
    "/joint_targets": ("sensor_msgs/msg/JointState", False),
    "/suction/on": ("std_msgs/msg/Bool", False),
    "/suction/held": ("std_msgs/msg/String", False),
    "/tf": ("tf2_msgs/msg/TFMessage", False),
    "/events": ("rcl_interfaces/msg/Log", False),
}
CAMERA_TOPICS = {
    "image": ("/camera/{}/image/compressed", "sensor_msgs/msg/CompressedImage"),
    "info": ("/camera/{}/camera_info", "sensor_msgs/msg/CameraInfo"),
}


def check_bag_target(out: Path, force: bool) -> None:
    """A bag may be written at `out`: its folder exists, and it is new, an empty folder, or (with
    force) an earlier bag. ConfigError saying which otherwise (before any work)."""
    if not out.parent.is_dir():
        raise ConfigError(
            f"cannot write bag {str(out)!r}: folder {str(out.parent)!r} does not exist; create it "
            "first"
        )
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        return
    if not is_bag_folder(out):
        raise ConfigError(
            f"cannot write bag {str(out)!r}: it exists and is no ROS 2 bag (no {BAG_METADATA}); "
            "expected a new or empty folder"
        )
    if not force:
        raise ConfigError(
            f"bag {str(out)!r} exists; expected a new folder (or --force to replace it)"
        )


def _messages(rec: Recording) -> list[tuple[int, str, object]]:
    """(t_ns, topic, message) of the whole run, in time order, then TOPICS order."""
    frames, config = rec.frames, rec.config
    names = list(config.profile.joint_names)
    objects = [o.name for o in config.objects]
    scene = SceneTransforms(rec.urdf, tuple(names), tuple(objects))
    t0 = int(frames.t_ns[0]) if len(frames) else 0
    out: list[tuple[int, str, object]] = [
        (t0, "/robot_description", m.string(rec.urdf)),
        (
            t0,
            "/tf_static",
            m.tf_message([m.transform(t0, m.WORLD, scene.root_link, (0, 0, 0, 0, 0, 0, 1))]),
        ),
    ]
    for i in range(len(frames)):
        t = int(frames.t_ns[i])
        held = int(frames.held_body[i])
        transforms = [m.transform(t, m.WORLD, PAD_TIP, frames.pad_pose[i])]
        transforms += [
            m.transform(t, m.WORLD, child, frames.object_poses[i, k])
            for k, child in enumerate(scene.object_frames)
        ]
        out += [
            (t, "/clock", m.clock(t)),
            (
                t,
                "/joint_states",
                m.joint_state(
                    t, names, frames.joint_q[i], frames.joint_qd[i], frames.joint_effort[i]
                ),
            ),
            (t, "/joint_targets", m.joint_state(t, names, frames.joint_target[i], [], [])),
            (t, "/suction/on", m.boolean(frames.suction_on[i])),
            (t, "/suction/held", m.string(objects[held] if 0 <= held < len(objects) else "")),
            (t, "/tf", m.tf_message(transforms)),
        ]
    for e in rec.events:
        out.append((e.t_ns, "/events", m.event_log(e.t_ns, e.kind, e.body, e.message, e.data)))
    out += _camera_messages(rec)
    order = {topic: k for k, topic in enumerate([*TOPICS, *_camera_topics(rec)])}
    # stable: a topic's messages keep their order
    out.sort(key=lambda item: (item[0], order[item[1]]))
    return out


def _camera_topics(rec: Recording) -> list[str]:
    return [
        pattern.format(name)
        for name in rec.cameras
        for pattern, _ in (CAMERA_TOPICS["info"], CAMERA_TOPICS["image"])
    ]


def _camera_messages(rec: Recording) -> list[tuple[int, str, object]]:
    """Each picture as CompressedImage with its CameraInfo, and the camera's pose on /tf."""
    specs = {spec.name: spec for spec in rec.config.cameras}
    out: list[tuple[int, str, object]] = []
    for name, track in rec.cameras.items():
        spec = specs.get(name)
        frame_id = spec.frame_id if spec else f"camera_{name}"
        for i in range(len(track)):
            t = int(track.t_ns[i])
            if spec is not None:
                info = m.camera_info(
                    t_ns=t,
                    frame_id=frame_id,
                    width_px=track.width_px,
                    height_px=track.height_px,
                    k=spec.intrinsics(),
                    p=spec.projection(),
                )
                out.append((t, CAMERA_TOPICS["info"][0].format(name), info))
            image = m.compressed_image(t, frame_id, track.format, track.data[i])
            out.append((t, CAMERA_TOPICS["image"][0].format(name), image))
            if len(track.pose) > i:
                tf = m.tf_message([m.transform(t, m.WORLD, frame_id, track.pose[i])])
                out.append((t, "/tf", tf))
    return out


def _write(rec: Recording, bag: Path) -> int:
    """The bag written at `bag` (a new path); the number of messages."""
    messages = _messages(rec)
    types = dict(TOPICS)
    for name in rec.cameras:
        for pattern, msgtype in CAMERA_TOPICS.values():
            types[pattern.format(name)] = (msgtype, False)
    used = {topic for _, topic, _ in messages}
    with Writer(bag, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            topic: writer.add_connection(
                topic,
                msgtype,
                typestore=m.TYPESTORE,
                offered_qos_profiles=m.offered_qos(latched),
            )
            for topic, (msgtype, latched) in types.items()
            if topic in used
        }
        for t_ns, topic, msg in messages:
            writer.write(connections[topic], t_ns, m.cdr(msg))
    return len(messages)


def write_bag(rec: Recording, out: Path, *, force: bool = False) -> int:
    """`rec` as a ROS 2 bag at `out`, written in a hidden folder beside it and renamed into place
    once complete (an earlier bag there is replaced only with force); the number of messages."""
    check_bag_target(out, force)
    tmp = out.with_name(f".{out.name}.{secrets.token_hex(4)}.tmp")
    tmp.mkdir()
    try:
        written = tmp / out.name  # the bag's own name: its MCAP file is named after its folder
        count = _write(rec, written)
        for path in sorted(written.iterdir()):
            fsync_file(path)
        if is_bag_folder(out):
            old = tmp / ".replaced"
            publish(out, old)
        publish(written, out)
    finally:
        with suppress(OSError):
            shutil.rmtree(tmp)
    return count


def bag_targets(paths: list[str], output: str | os.PathLike, force: bool) -> list[Path]:
    """Where each recording's bag goes: `output` itself for one recording; for several, a bag
    named after each (its stem) in the folder `output` (made if missing). Every target checked
    before any work: ConfigError naming the first that may not be written."""
    out = Path(output)
    if len(paths) == 1:
        targets = [out]
    else:
        stems = [Path(p).stem for p in paths]
        twice = sorted({s for s in stems if stems.count(s) > 1})
        if twice:
            raise ConfigError(
                f"recordings named {twice[0]!r} twice would go to one bag in {str(out)!r}; "
                "expected recordings of different names (export them apart)"
            )
        if out.exists() and not out.is_dir():
            raise ConfigError(
                f"cannot write bags into {str(out)!r}: it is a file; expected a folder"
            )
        if is_bag_folder(out):
            raise ConfigError(
                f"cannot write bags into {str(out)!r}: it is a ROS 2 bag; expected a folder of bags"
            )
        targets = [out / stem for stem in stems]
        if not out.exists() and not out.parent.is_dir():
            raise ConfigError(
                f"cannot write bags into {str(out)!r}: folder {str(out.parent)!r} does not exist; "
                "create it first"
            )
    for target in targets:
        if target.parent.is_dir():  # a folder of bags yet to be made holds none
            check_bag_target(target, force)
        for source in paths:
            inside = Path(source).resolve()
            if target.resolve() == inside or target.resolve() in inside.parents:
                raise ConfigError(
                    f"bag {str(target)!r} would replace its input {source!r}; expected another "
                    "output"
                )
    return targets


def export_bags(
    paths: list[str], output: str | os.PathLike, *, force: bool = False
) -> list[tuple[Path, int, int]]:
    """Each recording as a bag (bag_targets); (bag, messages, topics) of each. All recordings are
    loaded before any bag is written, so a bad one leaves nothing half done."""
    from twin.record.mcap.reader import load
    from twin.record.mcap.scan import is_bag

    for path in paths:
        if is_bag(path):
            raise ConfigError(
                f"{path!r} is a ROS 2 bag already; expected a twin recording (.mcap) to export"
            )
    targets = bag_targets(paths, output, force)
    recordings = [load(p) for p in paths]
    if len(paths) > 1:
        Path(output).mkdir(exist_ok=True)
    done = []
    for rec, target in zip(recordings, targets, strict=True):
        count = write_bag(rec, target, force=force)
        done.append((target, count, len(bag_topics(rec))))
    return done


def bag_topics(rec: Recording) -> list[str]:
    """The topics a recording's bag has."""
    topics = [t for t in TOPICS if t != "/events" or rec.events]
    return topics + _camera_topics(rec)
