"""The scene as `foxglove.FrameTransforms`: world -> robot root, every URDF joint at the frame's
joint values, the pad tip and every object — hand-encoded protobuf (the schema is Foxglove's).
"""

from __future__ import annotations

import math
import struct

from twin.model.quat import quat_from_rpy, quat_mul, rotate
from twin.model.types import Frame
from twin.record.mcap.wire import len_field, tag, varint
from twin.robot.urdf import UrdfJoint, parse_urdf, urdf_joints

WORLD = "world"
PAD_TIP = "pad_tip"
IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)

# translation (Vector3, field 4) and rotation (Quaternion, field 5) of a FrameTransform in one pack
_TAIL = struct.Struct("<BBBdBdBdBBBdBdBdBd")
_VEC_LEN, _QUAT_LEN = 27, 36


class _Joint:
    """One URDF joint (robot.urdf's reading of it), pre-digested so a transform costs a sine, a cosine
    and a pack."""

    def __init__(self, joint: UrdfJoint, column: int) -> None:
        self.kind = joint.kind
        self.moving = joint.moving
        self.xyz = joint.xyz
        self.q_origin = quat_from_rpy(*joint.rpy)
        self.rotated = any(abs(v) > 0.0 for v in joint.rpy)
        self.axis = joint.axis
        self.axis_in_parent = rotate(self.q_origin, self.axis)
        self.column = column  # index into Frame.joint_q, or -1 for a joint the frame does not carry
        self.names = len_field(2, joint.parent.encode()) + len_field(3, joint.child.encode())

    def pose(self, q: float) -> tuple[tuple[float, float, float], tuple[float, ...]]:
        if self.kind in ("revolute", "continuous"):
            s = math.sin(q / 2)
            motion = (self.axis[0] * s, self.axis[1] * s, self.axis[2] * s, math.cos(q / 2))
            return self.xyz, quat_mul(self.q_origin, motion) if self.rotated else motion
        if self.kind == "prismatic":
            a = self.axis_in_parent
            return (self.xyz[0] + a[0] * q, self.xyz[1] + a[1] * q, self.xyz[2] + a[2] * q), self.q_origin
        return self.xyz, self.q_origin


def _tail(xyz: tuple[float, ...], quat: tuple[float, ...]) -> bytes:
    """A FrameTransform's translation and rotation fields."""
    return _TAIL.pack(0x22, _VEC_LEN, 0x09, xyz[0], 0x11, xyz[1], 0x19, xyz[2],
                      0x2A, _QUAT_LEN, 0x09, quat[0], 0x11, quat[1], 0x19, quat[2], 0x21, quat[3])


def timestamp_field(t_ns: int) -> bytes:
    """google.protobuf.Timestamp as field 1 of the enclosing message."""
    seconds, nanos = divmod(t_ns, 1_000_000_000)
    body = tag(1, 0) + varint(seconds) + tag(2, 0) + varint(nanos)
    return b"\x0a" + varint(len(body)) + body


class SceneTransforms:
    """Builds one FrameTransforms message per viewed frame from a URDF and the scene's object names."""

    def __init__(self, urdf: str, joint_names: tuple[str, ...], object_names: tuple[str, ...]) -> None:
        root = parse_urdf(urdf)
        columns = {name: i for i, name in enumerate(joint_names)}
        joints = urdf_joints(root)
        self.joints = [_Joint(j, columns.get(j.name, -1)) for j in joints]
        children = {j.child for j in joints}
        roots = sorted(link.get("name") for link in root.iter("link") if link.get("name") not in children)
        self.root_link = roots[0] if roots else WORLD
        taken = {WORLD, PAD_TIP, *(link.get("name") for link in root.iter("link"))}
        self.object_frames = tuple(n if n not in taken else f"object_{n}" for n in object_names)
        root_names = len_field(2, WORLD.encode()) + len_field(3, self.root_link.encode())
        pad_names = len_field(2, WORLD.encode()) + len_field(3, PAD_TIP.encode())
        object_names = [len_field(2, WORLD.encode()) + len_field(3, n.encode()) for n in self.object_frames]
        # every transform, in message order: (names, constant tail or None, moving joint or None)
        static = [(root_names, _tail((0.0, 0.0, 0.0), IDENTITY_Q), None)]
        for j in self.joints:
            moving = j.column >= 0 and j.moving
            static.append((j.names, None if moving else _tail(*j.pose(0.0)), j if moving else None))
        self._items = static
        self._pad_names = pad_names
        self._object_names = object_names
        self._heads: dict[int, list[bytes]] = {}

    def _heads_for(self, ts_len: int) -> list[bytes]:
        """Per transform: its field tag and length, given the timestamp's encoded length."""
        names = [n for n, _, _ in self._items] + [self._pad_names, *self._object_names]
        heads = [b"\x0a" + varint(ts_len + len(n) + _TAIL.size) for n in names]
        self._heads[ts_len] = heads
        return heads

    def message(self, frame: Frame) -> bytes:
        """The serialized foxglove.FrameTransforms of one frame (every transform carries the frame's time)."""
        ts = timestamp_field(frame.t_ns)
        heads = self._heads.get(len(ts)) or self._heads_for(len(ts))
        q = frame.joint_q
        parts = []
        k = 0
        for names, tail, joint in self._items:
            if joint is not None:
                tail = _tail(*joint.pose(q[joint.column]))
            parts += (heads[k], ts, names, tail)
            k += 1
        pad = frame.pad_pose
        parts += (heads[k], ts, self._pad_names, _tail(pad[:3], pad[3:]))
        for names, pose in zip(self._object_names, frame.object_poses, strict=True):
            k += 1
            parts += (heads[k], ts, names, _tail(pose[:3], pose[3:]))
        return b"".join(parts)
