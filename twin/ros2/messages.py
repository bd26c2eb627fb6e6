"""ROS 2 message types and QoS of a twin bag: each topic, its standard message type and offered QoS,
and the messages built from a recording's values (rosbags' typestore; CDR serialization).

Message definitions and type hashes are ROS 2 Jazzy's. In rosbags' typestores, Humble's, Jazzy's
and Kilted's definitions and hashes of these types are the same, but for rcl_interfaces/msg/Log's
level constants (`byte` on Humble, `uint8` since): the same bytes on the wire.
"""

from __future__ import annotations

import json

import numpy as np
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
WORLD = "world"

_INFINITE = QosTime(9223372036, 854775807)  # rmw's "infinite" duration, as rosbag2 writes it


def offered_qos(latched: bool = False) -> list[Qos]:
    """One publisher's offered QoS as rosbag2 records it: reliable, volatile (transient-local for a
    latched topic such as /robot_description and /tf_static), history and depth as discovery
    reports them (unknown, 0), no deadline, lifespan or lease."""
    return [
        Qos(
            history=QosHistory.UNKNOWN,
            depth=0,
            reliability=QosReliability.RELIABLE,
            durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
            deadline=_INFINITE,
            lifespan=_INFINITE,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=_INFINITE,
            avoid_ros_namespace_conventions=False,
        )
    ]


def _t(name: str):
    return TYPESTORE.types[name]


def stamp(t_ns: int):
    """builtin_interfaces/msg/Time of `t_ns` nanoseconds."""
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return _t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(t_ns: int, frame_id: str = ""):
    return _t("std_msgs/msg/Header")(stamp=stamp(t_ns), frame_id=frame_id)


def cdr(msg) -> bytes:
    """The message serialized as CDR (little endian), as rosbag2 stores it."""
    return bytes(TYPESTORE.serialize_cdr(msg, msg.__msgtype__))


def joint_state(t_ns: int, names: list[str], position, velocity, effort):
    return _t("sensor_msgs/msg/JointState")(
        header=header(t_ns),
        name=names,
        position=np.asarray(position, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.asarray(effort, dtype=np.float64),
    )


def transform(t_ns: int, parent: str, child: str, pose) -> object:
    """geometry_msgs/msg/TransformStamped of a pose (x, y, z, qx, qy, qz, qw)."""
    x, y, z, qx, qy, qz, qw = (float(v) for v in pose)
    return _t("geometry_msgs/msg/TransformStamped")(
        header=header(t_ns, parent),
        child_frame_id=child,
        transform=_t("geometry_msgs/msg/Transform")(
            translation=_t("geometry_msgs/msg/Vector3")(x=x, y=y, z=z),
            rotation=_t("geometry_msgs/msg/Quaternion")(x=qx, y=qy, z=qz, w=qw),
        ),
    )


def tf_message(transforms: list) -> object:
    return _t("tf2_msgs/msg/TFMessage")(transforms=transforms)


def clock(t_ns: int):
    return _t("rosgraph_msgs/msg/Clock")(clock=stamp(t_ns))


def string(text: str):
    return _t("std_msgs/msg/String")(data=text)


def boolean(value: bool):
    return _t("std_msgs/msg/Bool")(data=bool(value))


_LOG = "rcl_interfaces/msg/Log"
# how loud each event kind is on /events: the rest are INFO
EVENT_LEVELS = {
    "task_error": "ERROR",
    "break": "WARN",
    "out_of_reach": "WARN",
    "joint_limit": "WARN",
    "cycle_failed": "WARN",
    "suction_empty": "WARN",
}


def event_log(t_ns: int, kind: str, body: str, message: str, data: dict):
    """An Event as rcl_interfaces/msg/Log: name `twin`, function the event's kind, msg the event as
    one JSON object (kind, body, message, data; keys sorted)."""
    cls = _t(_LOG)
    text = json.dumps(
        {"kind": kind, "body": body, "message": message, "data": data},
        sort_keys=True,
        separators=(",", ":"),
        default=str,
    )
    return cls(
        stamp=stamp(t_ns),
        level=getattr(cls, EVENT_LEVELS.get(kind, "INFO")),
        name="twin",
        msg=text,
        file="",
        function=kind,
        line=0,
    )


def compressed_image(t_ns: int, frame_id: str, fmt: str, data: bytes):
    return _t("sensor_msgs/msg/CompressedImage")(
        header=header(t_ns, frame_id),
        format=fmt,
        data=np.frombuffer(data, dtype=np.uint8),
    )


def camera_info(t_ns: int, frame_id: str, width_px: int, height_px: int, k, p):
    """An undistorted pinhole camera (plumb_bob with zero coefficients)."""
    return _t("sensor_msgs/msg/CameraInfo")(
        header=header(t_ns, frame_id),
        height=height_px,
        width=width_px,
        distortion_model="plumb_bob",
        d=np.zeros(5, dtype=np.float64),
        k=np.asarray(k, dtype=np.float64),
        r=np.eye(3, dtype=np.float64).reshape(9),
        p=np.asarray(p, dtype=np.float64),
        binning_x=0,
        binning_y=0,
        roi=_t("sensor_msgs/msg/RegionOfInterest")(
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )
