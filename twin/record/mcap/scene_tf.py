"""The scene as `foxglove.FrameTransforms`: world -> robot root, every URDF joint at the frame's
joint values, the pad tip and every object — hand-encoded protobuf (the schema is Foxglove's).
"""

from __future__ import annotations

import math
import struct
from operator import itemgetter

from twin.model.quat import quat_from_rpy, quat_mul, rotate
from twin.record.mcap.wire import VARINT, len_field, tag, varint
from twin.robot.urdf import UrdfJoint, parse_urdf, urdf_joints

WORLD = "world"
PAD_TIP = "pad_tip"
IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)

# A FrameTransform's translation (Vector3, field 4) and rotation (Quaternion, field 5): the constant
# bytes (tags, lengths) around its seven numbers x, y, z, qx, qy, qz, qw, in order.
_TAIL = (
    b"\x22\x1b\x09",
    0,
    b"\x11",
    1,
    b"\x19",
    2,
    b"\x2a\x24\x09",
    3,
    b"\x11",
    4,
    b"\x19",
    5,
    b"\x21",
    6,
)
_TAIL_BYTES = sum(len(p) if isinstance(p, bytes) else 8 for p in _TAIL)
_DOUBLE = struct.Struct("<d")
_SECONDS_TAG, _NANOS_TAG = tag(1, VARINT), tag(2, VARINT)  # a Timestamp's fields


class _Joint:
    """One URDF joint (robot.urdf's reading of it), pre-digested so a transform costs a sine, a
    cosine and a pack."""

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
            return (
                self.xyz[0] + a[0] * q,
                self.xyz[1] + a[1] * q,
                self.xyz[2] + a[2] * q,
            ), self.q_origin
        return self.xyz, self.q_origin


def _tail(xyz: tuple[float, ...], quat: tuple[float, ...]) -> bytes:
    """A FrameTransform's translation and rotation fields."""
    values = (*xyz, *quat)
    return b"".join(p if isinstance(p, bytes) else _DOUBLE.pack(values[p]) for p in _TAIL)


def timestamp_field(t_ns: int) -> bytes:
    """google.protobuf.Timestamp as field 1 of the enclosing message."""
    seconds, nanos = divmod(t_ns, 1_000_000_000)
    body = _SECONDS_TAG + varint(seconds) + _NANOS_TAG + varint(nanos)
    return b"\x0a" + varint(len(body)) + body


class SceneTransforms:
    """Builds one FrameTransforms message per viewed frame from a URDF and the scene's object
    names."""

    def __init__(
        self, urdf: str, joint_names: tuple[str, ...], object_names: tuple[str, ...]
    ) -> None:
        root = parse_urdf(urdf)
        columns = {name: i for i, name in enumerate(joint_names)}
        joints = urdf_joints(root)
        self.joints = [_Joint(j, columns.get(j.name, -1)) for j in joints]
        children = {j.child for j in joints}
        roots = sorted(
            link.get("name") for link in root.iter("link") if link.get("name") not in children
        )
        self.root_link = roots[0] if roots else WORLD
        taken = {WORLD, PAD_TIP, *(link.get("name") for link in root.iter("link"))}
        self.object_frames = tuple(n if n not in taken else f"object_{n}" for n in object_names)
        root_names = len_field(2, WORLD.encode()) + len_field(3, self.root_link.encode())
        pad_names = len_field(2, WORLD.encode()) + len_field(3, PAD_TIP.encode())
        object_names = [
            len_field(2, WORLD.encode()) + len_field(3, n.encode()) for n in self.object_frames
        ]
        # the robot's transforms, in message order: (names, constant tail or None, moving joint or
        # None)
        static = [(root_names, _tail((0.0, 0.0, 0.0), IDENTITY_Q), None)]
        for j in self.joints:
            moving = j.column >= 0 and j.moving
            static.append((j.names, None if moving else _tail(*j.pose(0.0)), j if moving else None))
        # then the pad's and the objects': (names, constant tail, or None where its numbers change)
        self._transforms = [(names, tail) for names, tail, _ in static]
        self._transforms += [(names, None) for names in (pad_names, *object_names)]
        self._moving = [joint for _, _, joint in static if joint is not None]
        self._encoders: dict[int, tuple[struct.Struct, itemgetter, tuple[bytes, ...]]] = {}

    def _encoder(self, ts_len: int) -> tuple[struct.Struct, itemgetter, tuple[bytes, ...]]:
        """The whole message as one struct, given the timestamp's encoded length, and which value
        goes in each of its places: message() fills it from one tuple (timestamp, the moving joints'
        numbers, the poses' numbers, the constant pieces), so a message costs one pack (pick_place's
        scene: about 5 us a message from a row, where a Frame from the row and a pack per transform
        cost 7.3)."""
        pieces: list[bytes | int] = []  # constant bytes, or a value's index in that tuple
        at = 1  # the next number's index (0 is the timestamp)
        for names, tail in self._transforms:
            pieces += [b"\x0a" + varint(ts_len + len(names) + _TAIL_BYTES), 0, names]
            if tail is not None:
                pieces.append(tail)
            else:
                pieces += [p if isinstance(p, bytes) else at + p for p in _TAIL]
                at += 7
        merged: list[bytes | int] = []  # adjacent constants as one piece
        for p in pieces:
            if isinstance(p, bytes) and merged and isinstance(merged[-1], bytes):
                merged[-1] += p
            else:
                merged.append(p)
        formats, places, consts = ["<"], [], []
        for p in merged:
            if isinstance(p, bytes):
                formats.append(f"{len(p)}s")
                places.append(at + len(consts))
                consts.append(p)
            else:
                formats.append(f"{ts_len}s" if p == 0 else "d")
                places.append(p)
        encoder = (struct.Struct("".join(formats)), itemgetter(*places), tuple(consts))
        self._encoders[ts_len] = encoder
        return encoder

    def message(self, t_ns: int, joint_q, poses) -> bytes:
        """The serialized foxglove.FrameTransforms of one frame (every transform carries the frame's
        time): `joint_q` the frame's joint values, `poses` the pad's pose then each object's, seven
        numbers each (x, y, z, qx, qy, qz, qw), flat."""
        ts = timestamp_field(t_ns)
        form, places, consts = self._encoders.get(len(ts)) or self._encoder(len(ts))
        numbers = []
        for joint in self._moving:
            xyz, quat = joint.pose(joint_q[joint.column])
            numbers += xyz
            numbers += quat
        return form.pack(*places((ts, *numbers, *poses, *consts)))
