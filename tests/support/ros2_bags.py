"""A robot's log as a test stands it in: a ROS 2 bag of /joint_states written with rosbags from a
twin run, at another rate (the run interpolated linearly), stamped from a wall-clock epoch, with
time before the motion starts, noise, a bias on one joint, or other joint names."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)  # another distribution's definitions than twin's
JOINT_STATE = TYPESTORE.types["sensor_msgs/msg/JointState"]
HEADER = TYPESTORE.types["std_msgs/msg/Header"]
TIME = TYPESTORE.types["builtin_interfaces/msg/Time"]
EPOCH_NS = 1_700_000_000 * 10**9  # 2023-11-14, a wall-clock stamp


def joint_bag(
    rec,
    out: Path,
    *,
    rate_hz: float = 100.0,
    lead_s: float = 0.0,
    noise_rad: float = 0.0,
    bias: tuple[str, float] | None = None,
    names: list[str] | None = None,
    velocity: bool = False,
    gripper_every: int = 0,
    seed: int = 0,
) -> Path:
    """The run's joints sampled at rate_hz from -lead_s (at rest until 0) to its end, each message
    stamped EPOCH_NS + lead_s + its time and logged 3 ms later; noise_rad Gaussian on each position;
    bias (joint, rad) added to one joint; names instead of the twin's; velocity: also velocities;
    gripper_every: every that many samples also a message of a gripper joint alone (its own
    controller's).
    Returns out (a new bag folder, MCAP storage, metadata version 8)."""
    t_s = rec.frames.t_ns * 1e-9
    q, qd = rec.frames.joint_q, rec.frames.joint_qd
    twin_names = list(rec.config.profile.joint_names)
    rng = np.random.default_rng(seed)
    samples = np.arange(-lead_s, t_s[-1], 1.0 / rate_hz)
    with Writer(out, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", JOINT_STATE.__msgtype__, typestore=TYPESTORE)
        for u in samples:
            pos = np.array([np.interp(u, t_s, q[:, k]) for k in range(q.shape[1])])
            pos += noise_rad * rng.standard_normal(len(pos))
            if bias:
                pos[twin_names.index(bias[0])] += bias[1]
            vel = np.array([np.interp(u, t_s, qd[:, k]) for k in range(q.shape[1])])
            ns = EPOCH_NS + round((lead_s + u) * 1e9)  # exact: 1.7e18 as a float is not
            msg = JOINT_STATE(
                header=HEADER(stamp=TIME(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                name=names or twin_names,
                position=pos,
                velocity=vel if velocity else np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(
                conn, ns + 3_000_000, TYPESTORE.serialize_cdr(msg, JOINT_STATE.__msgtype__)
            )
            if gripper_every and round(u * rate_hz) % gripper_every == 0:
                grip = JOINT_STATE(
                    header=HEADER(stamp=TIME(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                    name=["gripper"],
                    position=np.array([0.01]),
                    velocity=np.zeros(0),
                    effort=np.zeros(0),
                )
                data = TYPESTORE.serialize_cdr(grip, JOINT_STATE.__msgtype__)
                writer.write(conn, ns + 4_000_000, data)
    return out
