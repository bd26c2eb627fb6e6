"""Reading a ROS 2 bag (a folder with metadata.yaml, or one MCAP file of profile `ros2`) as a joint
log: its /joint_states by joint name, and its /tf where it has one (rosbags' reader; CDR).

Each sample's time is its message's header stamp (the robot's own clock), or the time it was logged
when the stamps are all zero.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from twin.model.errors import RecordingError, TwinError
from twin.model.joint_log import JointLog
from twin.model.recording import Recording
from twin.record.mcap.scan import is_bag  # noqa: F401 - read here before it moved to scan
from twin.record.mcap.scene_tf import SceneTransforms
from twin.ros2.messages import TYPESTORE

JOINT_STATES = "/joint_states"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
TF = ("/tf", "/tf_static")


def run_log(rec: Recording) -> JointLog:
    """A twin run as a JointLog whose /tf frames are named as its exported bag names them (an
    object named like a robot link is `object_NAME` there)."""
    scene = SceneTransforms(
        rec.urdf,
        tuple(rec.config.profile.joint_names),
        tuple(o.name for o in rec.config.objects),
    )
    return JointLog.from_recording(rec, scene.object_frames)


def _stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class _Samples:
    """The /joint_states messages gathered by joint name."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.names: list[str] = []
        self.header_ns: list[int] = []
        self.log_ns: list[int] = []
        self.rows: dict[str, list[list[float]]] = {"position": [], "velocity": [], "effort": []}
        self.has = {"velocity": True, "effort": True}

    def take(self, log_ns: int, msg) -> None:
        names = list(msg.name)
        if not self.names:
            self.names = names
        index = {name: k for k, name in enumerate(names)}
        missing = [name for name in self.names if name not in index]
        if missing or len(msg.position) != len(names):
            raise RecordingError(
                f"bag {self.where!r}: a {JOINT_STATES} message at {log_ns} ns has joints {names} "
                f"with {len(msg.position)} positions; expected positions of {self.names}"
            )
        order = [index[name] for name in self.names]
        self.rows["position"].append([float(msg.position[k]) for k in order])
        for key in ("velocity", "effort"):
            values = getattr(msg, key)
            if len(values) != len(names):
                self.has[key] = False
            elif self.has[key]:
                self.rows[key].append([float(values[k]) for k in order])
        self.header_ns.append(_stamp_ns(msg.header.stamp))
        self.log_ns.append(log_ns)

    def log(self, topics: dict[str, str], tf: dict) -> JointLog:
        t = self.header_ns if any(self.header_ns) else self.log_ns
        t_ns = np.asarray(t, dtype=np.int64)
        order = np.argsort(t_ns, kind="stable")
        if np.any(np.diff(t_ns[order]) <= 0):
            raise RecordingError(
                f"bag {self.where!r}: two {JOINT_STATES} messages share a time stamp; "
                "expected increasing stamps"
            )

        def column(key: str) -> np.ndarray | None:
            if key != "position" and not self.has[key]:
                return None
            return np.asarray(self.rows[key], dtype=np.float64).reshape(-1, len(self.names))[order]

        return JointLog(
            tuple(self.names),
            t_ns[order],
            column("position"),
            column("velocity"),
            column("effort"),
            path=self.where,
            topics=topics,
            tf=tf,
        )


def read_bag(path: str | os.PathLike) -> JointLog:
    """The bag's /joint_states (and /tf) as a JointLog; RecordingError naming the bag and what is
    wrong with it (unreadable, no /joint_states, stamps that repeat). Messages of another set of
    joints than the most common one's (a gripper's own controller) are left out (its notes say)."""
    where = str(path)
    groups: dict[frozenset[str], _Samples] = {}  # by joint names: a controller may log its own
    tf: dict[str, list] = {}
    try:
        with Reader(Path(path)) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            wanted = [c for c in reader.connections if c.topic in (JOINT_STATES, *TF)]
            if JOINT_STATES not in topics or topics[JOINT_STATES] != JOINT_STATE_TYPE:
                raise RecordingError(
                    f"bag {where!r} has no {JOINT_STATES} topic of type {JOINT_STATE_TYPE}; "
                    f"its topics: {', '.join(sorted(topics)) or 'none'}"
                )
            for connection, log_ns, data in reader.messages(connections=wanted):
                msg = TYPESTORE.deserialize_cdr(data, connection.msgtype)
                if connection.topic == JOINT_STATES:
                    groups.setdefault(frozenset(msg.name), _Samples(where)).take(log_ns, msg)
                elif connection.msgtype == "tf2_msgs/msg/TFMessage":
                    for t in msg.transforms:
                        tr, q = t.transform.translation, t.transform.rotation
                        pose = (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
                        tf.setdefault(t.child_frame_id, []).append(
                            (_stamp_ns(t.header.stamp), pose)
                        )
    except TwinError:
        raise
    except Exception as err:  # a foreign file: rosbags' YAML, CDR and MCAP errors
        kind = "" if isinstance(err, ReaderError) else f"{type(err).__name__}: "
        text = " ".join(str(err).split())[:200]  # one line, however long the parser's message
        raise RecordingError(f"cannot read ROS 2 bag {where!r}: {kind}{text}") from err
    if not groups:
        raise RecordingError(f"bag {where!r} has no {JOINT_STATES} messages; expected at least one")
    samples = max(groups.values(), key=lambda g: len(g.log_ns))  # the first of the most common
    notes = [
        f"{where}: {len(g.log_ns)} {JOINT_STATES} messages of other joints "
        f"({', '.join(g.names)}) left out"
        for g in groups.values()
        if g is not samples
    ]
    tf_arrays = {
        child: (
            np.array([t for t, _ in rows], dtype=np.int64),
            np.array([p for _, p in rows], dtype=np.float64),
        )
        for child, rows in tf.items()
    }
    log = samples.log(topics, tf_arrays)
    log.notes = notes
    return log
