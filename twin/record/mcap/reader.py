"""Reading recordings: `load(path)` -> Recording (frames as numpy columns, commands, events,
config).

One pass over the file's records (mcap.scan); the twin's blocks are decoded with a numpy fast
path (tests check it against the standard protobuf decoder). `scan(path, strict=False)` stops at
the first broken record instead of failing, which is what `twin recover` and `twin info` use.

Memory does not grow with messages a reader does not interpret: `scan(topics=...)` hands over only
the messages of the topics asked for, and counts the rest by channel. `load` takes each message as
it is read (a block's fields, a Command, an Event, a picture), so a message that does not parse
fails at once and no message object is kept: what stays is what the Recording holds.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.records import Attachment, Channel, Footer, Header, Metadata, Schema

from twin.model import fields as F
from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import CAMERA_FRAME_PREFIX, CameraTrack
from twin.model.json_values import shown
from twin.model.types import Command, Event
from twin.record.mcap import scan as mcap_scan
from twin.record.mcap import schemas as S
from twin.record.mcap import strict_json, wire
from twin.record.mcap.metadata import located_config, parse_config, parse_run
from twin.record.tables import RecordingWithTables

MAGIC = mcap_scan.MAGIC
Message = mcap_scan.Message


@dataclass
class Scan:
    """Every record read from a file, in file order, and whether the file ended cleanly. `messages`
    holds the messages of the topics the scan kept (all, unless it was told which, or handed them
    on); `counts` the number of messages on each channel id, kept or not."""

    path: str
    size_bytes: int
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    counts: dict[int, int] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[Attachment] = field(default_factory=list)
    library: str = ""
    header: bool = False  # an MCAP header record was read
    complete: bool = False  # the footer was reached
    problem: str = ""  # why reading stopped early
    # the channel ids whose messages are handed on
    _keep: set[int] = field(default_factory=set, repr=False)
    # topics no longer kept (stop_keeping)
    _dropped: set[str] = field(default_factory=set, repr=False)

    def stop_keeping(self, topic: str) -> None:
        """From now on, only count the messages of `topic` (a consumer that has seen enough of
        them)."""
        self._dropped.add(topic)
        self._keep.difference_update(cid for cid, c in self.channels.items() if c.topic == topic)

    @property
    def message_count(self) -> int:
        """Every message read, on any channel (kept or only counted)."""
        return sum(self.counts.values())

    def message_count_of(self, topic: str) -> int:
        """The messages read on the channels of one topic."""
        return sum(
            n
            for cid, n in self.counts.items()
            if cid in self.channels and self.channels[cid].topic == topic
        )

    def topic_of(self, message: Message) -> str:
        return self.channels[message.channel_id].topic

    def by_topic(self) -> dict[str, list[Message]]:
        out: dict[str, list[Message]] = {c.topic: [] for c in self.channels.values()}
        for m in self.messages:
            out[self.channels[m.channel_id].topic].append(m)
        return out


# (the scan so far, the message's topic, the message)
Consume = Callable[[Scan, str, Message], None]


def block_steps(message: Message) -> np.ndarray:
    """The steps a block message (/twin/joints, /twin/suction, /twin/poses) holds."""
    return wire.array_of(wire.split_fields(message.data), S.STEP, "<i8")


def open_checked(path: str | Path) -> tuple[str, int]:
    """The path as text and its size; RecordingError for a missing, empty, non-file or non-MCAP
    path. Only a regular file is opened: a FIFO, socket or device would block or never end."""
    where = str(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise RecordingError(f"recording {where!r} does not exist") from None
    except (OSError, ValueError) as err:
        raise RecordingError(
            f"cannot read recording {where!r}: {getattr(err, 'strerror', None) or err}"
        ) from err
    if stat.S_ISDIR(mode):
        bag = (
            " (a ROS 2 bag: twin diff and twin.load read it)"
            if mcap_scan.is_bag_folder(path)
            else ""
        )
        raise RecordingError(f"recording {where!r} is a directory{bag}; expected an MCAP file")
    if not stat.S_ISREG(mode):
        raise RecordingError(
            f"recording {where!r} is not a regular file (a FIFO, socket or device); expected an "
            "MCAP file"
        )
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            head = f.read(len(MAGIC))
    except OSError as err:
        raise RecordingError(f"cannot read recording {where!r}: {err.strerror or err}") from err
    if size == 0:
        raise RecordingError(f"recording {where!r} is empty (0 bytes); expected an MCAP file")
    if head != MAGIC[: len(head)] or len(head) < len(MAGIC):
        if head == MAGIC[: len(head)]:
            raise RecordingError(
                f"recording {where!r} is truncated: {size} bytes, shorter than the MCAP magic"
            )
        raise RecordingError(
            f"{where!r} is not an MCAP file (it does not start with the MCAP magic bytes)"
        )
    if mcap_scan.profile(path) == mcap_scan.ROS2_PROFILE:
        raise RecordingError(
            f"{where!r} is a ROS 2 bag's MCAP file (profile ros2), not a twin recording; twin diff "
            "and twin.load read it"
        )
    return where, size


def scan(
    path: str | Path,
    *,
    strict: bool = True,
    topics: Collection[str] | Callable[[str], bool] | None = None,
    consume: Consume | None = None,
) -> Scan:
    """Read every record. strict: a file that ends without a footer or with a damaged record is a
    RecordingError; otherwise reading stops there and `problem` says why.

    topics: the topics whose messages are kept (a collection, or a test of the topic); None: every
    topic. The others' messages are only counted. consume: called with each kept message as it is
    read, instead of keeping it in `messages` (what it raises ends the scan)."""
    where, size = open_checked(path)
    out = Scan(where, size)
    wanted = (
        (lambda _: True)
        if topics is None
        else topics
        if callable(topics)
        else frozenset(topics).__contains__
    )
    keep = out._keep
    footer = False
    with open(where, "rb") as f:
        try:
            for record in mcap_scan.records(f, size, keep=keep, counts=out.counts):
                kind = type(record)
                if kind is Message:
                    if consume is None:
                        out.messages.append(record)
                    else:
                        consume(out, out.channels[record.channel_id].topic, record)
                elif kind is Channel:
                    known = out.channels.get(record.id)
                    if known is not None and known.topic != record.topic:
                        raise mcap_scan.Damaged(
                            f"channel {record.id} is registered as {known.topic[:60]!r} and "
                            f"again as {record.topic[:60]!r}"
                        )
                    out.channels[record.id] = record
                    if wanted(record.topic) and record.topic not in out._dropped:
                        keep.add(record.id)
                elif kind is Schema:
                    out.schemas[record.id] = record
                elif kind is Metadata:
                    out.metadata[record.name] = dict(record.metadata)
                elif kind is Attachment:
                    out.attachments.append(record)
                elif kind is Footer:
                    footer = True
                elif kind is Header:
                    out.library, out.header = record.library, True
            out.complete = footer  # the footer, its closing magic and nothing after them
        except (mcap_scan.Truncated, mcap_scan.Damaged) as err:
            out.problem = str(err)
        except OSError as err:
            raise RecordingError(f"cannot read recording {where!r}: {err.strerror or err}") from err
    if not out.complete and not out.problem:
        out.problem = "the file ends without an MCAP footer"
    if not out.header:
        raise RecordingError(
            f"recording {where!r} is truncated or damaged: no complete MCAP header in its "
            f"{size} bytes"
        )
    if strict and not out.complete:
        raise RecordingError(
            f"recording {where!r} is truncated or damaged ({out.problem}) after "
            f"{out.message_count} readable "
            f"messages; `twin recover {where} -o FIXED.mcap` restores its readable part"
        )
    return out


def load(path: str | Path) -> RecordingWithTables:
    """A finalized (or recovered) recording, as a Recording."""
    builder = RecordingBuilder()
    return builder.recording(scan(path, strict=True, topics=builder.wants, consume=builder.take))


def recording_from_scan(s: Scan) -> RecordingWithTables:
    """The Recording of a scan that kept every message (scan(path) without topics or consume)."""
    builder = RecordingBuilder()
    for m in s.messages:
        topic = s.topic_of(m)
        if builder.wants(topic):
            builder.take(s, topic, m)
    return builder.recording(s)


_CAMERA_FRAME = CAMERA_FRAME_PREFIX.encode()


def _is_image_topic(topic: str) -> bool:
    return topic.startswith("/camera/") and topic.endswith("/image")


class RecordingBuilder:
    """Takes a recording's messages one by one as they are read (scan's consume) and keeps only what
    the Recording holds: the blocks' fields as bytes, Commands, Events, the URDF, the pictures."""

    FIXED = frozenset(
        (*S.BLOCK_TOPICS.values(), S.COMMANDS.topic, S.EVENTS.topic, S.ROBOT_DESCRIPTION.topic)
    )

    def __init__(self) -> None:
        self.blocks = {topic: BlockParts(block, topic) for block, topic in S.BLOCK_TOPICS.items()}
        self.commands: list[Command] = []
        self.events: list[Event] = []
        self.urdf: str | None = None
        self._config: TwinConfig | None = None
        # image topic -> (t_ns, format, data)
        self._pictures: dict[str, list[tuple[int, str, bytes]]] = {}
        # pictures read before the configuration (twin never writes)
        self._early: list[tuple[str, Message]] = []
        # (frame_id, t_ns) -> pose
        self._camera_poses: dict[tuple[str, int], tuple[float, ...]] = {}

    def wants(self, topic: str) -> bool:
        return topic in self.FIXED or _is_image_topic(topic) or topic == S.TF.topic

    def take(self, s: Scan, topic: str, m: Message) -> None:
        where = s.path
        blocks = self.blocks.get(topic)
        if blocks is not None:
            blocks.add(m.data, where)
        elif topic == S.COMMANDS.topic:
            self.commands.append(parse_command(m.data, where))
        elif topic == S.EVENTS.topic:
            self.events.append(parse_event(m.data, where))
        elif topic == S.ROBOT_DESCRIPTION.topic:
            if self.urdf is None:
                self.urdf = parse_robot_description(m.data, where)
        elif topic == S.TF.topic:
            if self._without_cameras(s):
                # no camera: no picture's pose to read (the scene's /tf is the frames')
                s.stop_keeping(topic)
            elif _CAMERA_FRAME in m.data:
                # a picture's pose; the scene's own transforms are skipped
                self._camera_pose(m.data, where)
        elif self._config is None and S.META_CONFIG not in s.metadata:
            self._early.append((topic, m))
        else:
            self._picture(self._configured(s), topic, m.data, where)

    def _configured(self, s: Scan) -> TwinConfig:
        if self._config is None:
            self._config = parse_config(s.metadata, repr(s.path))
        return self._config

    def _without_cameras(self, s: Scan) -> bool:
        """True once the configuration is read and has no camera (a bad one is reported by
        recording())."""
        if S.META_CONFIG not in s.metadata:
            return False
        try:
            return not self._configured(s).cameras
        except RecordingError:
            return False

    def _camera_pose(self, data: bytes, where: str) -> None:
        """The camera poses a /tf message holds, by camera frame and time (what the picture was
        taken from)."""
        from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
        from google.protobuf.message import DecodeError

        message = FrameTransforms()
        try:
            message.ParseFromString(data)
        except DecodeError as err:
            raise RecordingError(
                f"recording {where!r}: a {S.TF.topic} message is not a FrameTransforms: {err}"
            ) from err
        for t in message.transforms:
            if t.child_frame_id.startswith(CAMERA_FRAME_PREFIX):
                t_ns = t.timestamp.seconds * 1_000_000_000 + t.timestamp.nanos
                self._camera_poses[(t.child_frame_id, t_ns)] = (
                    t.translation.x,
                    t.translation.y,
                    t.translation.z,
                    t.rotation.x,
                    t.rotation.y,
                    t.rotation.z,
                    t.rotation.w,
                )

    def _picture(self, config: TwinConfig, topic: str, data: bytes, where: str) -> None:
        """A picture on a configured camera's channel, checked now (others are left out, as
        before)."""
        spec = next((c for c in config.cameras if S.image_channel(c.name).topic == topic), None)
        if spec is None:
            return
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
        from google.protobuf.message import DecodeError

        picture = CompressedImage()
        try:
            picture.ParseFromString(data)
        except DecodeError as err:
            raise RecordingError(
                f"recording {where!r}: a {topic} message is not a CompressedImage: {err}"
            ) from err
        t_ns = picture.timestamp.seconds * 1_000_000_000 + picture.timestamp.nanos
        if picture.format != spec.format or t_ns % config.dt_ns or not 0 <= t_ns <= S.MAX_T_NS:
            raise RecordingError(
                f"recording {where!r}: a {topic} picture at {t_ns} ns in {picture.format!r}; "
                f"expected {spec.format!r} at a whole step of {config.dt_ns} ns"
            )
        self._pictures.setdefault(topic, []).append((t_ns, picture.format, picture.data))

    def recording(self, s: Scan) -> RecordingWithTables:
        """The Recording, once every message has been taken."""
        config = located_config(self._configured(s), s.path)
        for topic, m in self._early:
            self._picture(config, topic, m.data, s.path)
        self._early.clear()
        frames = frames_of(*self.blocks.values(), n_objects=len(config.objects), where=s.path)
        tracks = {}
        for spec in config.cameras:
            pictures = self._pictures.get(S.image_channel(spec.name).topic, [])
            times = np.array([t for t, _, _ in pictures], dtype=np.int64)
            poses = [self._camera_poses.get((spec.frame_id, t)) for t, _, _ in pictures]
            pose = np.array(
                poses if all(p is not None for p in poses) else [], dtype=np.float64
            ).reshape(-1, 7)
            tracks[spec.name] = CameraTrack(
                name=spec.name,
                width_px=spec.width_px,
                height_px=spec.height_px,
                format=spec.format,
                step=times // config.dt_ns,
                t_ns=times,
                data=[d for _, _, d in pictures],
                source=s.path,
                pose=pose,
            )
        meta = {
            name: dict(record)
            for name, record in sorted(s.metadata.items())
            if name not in (S.META_CONFIG, S.META_RUN)
        }
        return RecordingWithTables(
            config=config,
            frames=frames,
            commands=self.commands,
            events=self.events,
            run=parse_run(s.metadata, repr(s.path)),
            meta=meta,
            finalized=S.META_FINALIZED in s.metadata and s.complete,
            urdf=self.urdf or "",
            path=s.path,
            assets={a.name: a.data for a in s.attachments},
            cameras=tracks,
        )


def parse_robot_description(data: bytes, where: str) -> str:
    """The URDF text of a /robot_description message ({"data": URDF}); RecordingError otherwise."""
    urdf = _json_message(data, S.ROBOT_DESCRIPTION.topic, where).get("data")
    if not isinstance(urdf, str):
        raise RecordingError(
            f"recording {where!r}: the {S.ROBOT_DESCRIPTION.topic} message has no string "
            "'data'; expected {\"data\": URDF text}"
        )
    return urdf


def _json_message(data: bytes, what: str, where: str) -> dict:
    try:
        value = strict_json.loads(data)
    except ValueError as err:
        raise RecordingError(f"recording {where!r}: a {what} message is not JSON: {err}") from err
    if not isinstance(value, dict):
        raise RecordingError(f"recording {where!r}: a {what} message is not a JSON object")
    return value


def _whole(v: dict, name: str, limit: int) -> int:
    value = v.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
        raise ValueError(f"{name} {shown(value, 40)} is not a whole number 0..{limit}")
    return value


def _text(v: dict, name: str) -> str:
    value = v.get(name)
    if not isinstance(value, str):
        raise TypeError(f"{name} {shown(value, 40)} is not a string")
    return value


def _object(v: dict, name: str) -> dict:
    value = v.get(name)
    if not isinstance(value, dict):
        raise TypeError(f"{name} {shown(value, 40)} is not a JSON object")
    return value


def parse_command(data: bytes, where: str) -> Command:
    """A /commands message: step (0..MAX_STEP), kind, args; finite numbers only (the args themselves
    are checked by Twin.apply when replayed). RecordingError naming the field otherwise."""
    v = _json_message(data, "command", where)
    try:
        return Command(
            step=_whole(v, "step", S.MAX_STEP), kind=_text(v, "kind"), args=_object(v, "args")
        )
    except (TypeError, ValueError) as err:
        raise RecordingError(
            f"recording {where!r}: malformed command {shown(v, 120, as_json=True)}: {err}"
        ) from err


def parse_event(data: bytes, where: str) -> Event:
    """A /twin/events message: step, t_ns, kind, body, message, data; RecordingError naming the
    field otherwise."""
    v = _json_message(data, "event", where)
    try:
        return Event(
            step=_whole(v, "step", S.MAX_STEP),
            t_ns=_whole(v, "t_ns", S.MAX_T_NS),
            kind=_text(v, "kind"),
            body=_text(v, "body"),
            message=_text(v, "message"),
            data=_object(v, "data"),
        )
    except (TypeError, ValueError) as err:
        raise RecordingError(
            f"recording {where!r}: malformed event {shown(v, 120, as_json=True)}: {err}"
        ) from err


class BlockParts:
    """The numbered fields of one block channel's messages, as the raw bytes of each, message after
    message (model.fields says which field is where); a message is split when it is added."""

    def __init__(self, block: str, topic: str) -> None:
        self.block, self.topic = block, topic
        # step first; t_ns is every block's, taken from the first (the frames' steps must agree)
        self.fields = tuple(
            f for f in F.block_fields(block) if f.name != "t_ns" or block == F.BLOCKS[0]
        )
        self.parts: list[list[bytes]] = [[] for _ in self.fields]

    def add(self, data: bytes, where: str) -> None:
        try:
            fields = wire.split_fields(data)
        except RecordingError as err:
            raise RecordingError(
                f"recording {where!r}: a {self.topic} block is malformed: {err}"
            ) from err
        raws = [wire.raw_of(fields, f.number, f.wire) for f in self.fields]
        # twin writes a block when it holds frames: an empty one costs memory, says nothing
        if not raws[0]:
            raise RecordingError(
                f"recording {where!r}: a {self.topic} block holds no frame; expected at least one"
            )
        for part, raw in zip(self.parts, raws, strict=True):
            part.append(raw)

    def arrays(self, where: str) -> list[np.ndarray]:
        """Each field's values, every message's concatenated (the parts are released)."""
        out = []
        for f, parts in zip(self.fields, self.parts, strict=True):
            raw = b"".join(parts)
            parts.clear()
            if len(raw) % np.dtype(f.wire).itemsize:
                raise RecordingError(
                    f"recording {where!r}: a {self.topic} field is not a whole number of {f.wire} "
                    "values"
                )
            out.append(np.frombuffer(raw, dtype=f.wire).copy())
        return out


def decode_frames(
    joints: list[Message], suction: list[Message], poses: list[Message], n_objects: int, where: str
) -> FrameColumns:
    """FrameColumns from the three block channels' messages; RecordingError if they disagree."""
    blocks = []
    for (block, topic), messages in zip(
        S.BLOCK_TOPICS.items(), (joints, suction, poses), strict=True
    ):
        parts = BlockParts(block, topic)
        for m in messages:
            parts.add(m.data, where)
        blocks.append(parts)
    return frames_of(*blocks, n_objects=n_objects, where=where)


def frames_of(*blocks: BlockParts, n_objects: int, where: str) -> FrameColumns:
    """FrameColumns from the three block channels' parts (in model.fields' block order);
    RecordingError if they disagree."""
    n_joints = 4
    columns: dict[str, np.ndarray] = {}
    steps = []
    for parts in blocks:
        for f, array in zip(parts.fields, parts.arrays(where), strict=True):
            if f.name == "step":
                steps.append(array)
            elif f.name not in columns:
                columns[f.name] = array
    step = columns["step"] = steps[0]
    n = len(step)
    if not all(np.array_equal(step, other) for other in steps[1:]):
        raise RecordingError(
            f"recording {where!r}: the joint, suction and pose channels cover different steps "
            f"({', '.join(str(len(s)) for s in steps)} frames)"
        )
    if n > 1 and not np.all(np.diff(step) > 0):
        raise RecordingError(f"recording {where!r}: frame steps are not increasing")
    for f in F.FRAME_FIELDS:
        shape = (n, *f.trailing(n_joints, n_objects))
        size = int(np.prod(shape, dtype=np.int64))
        if columns[f.name].size != size:
            raise RecordingError(
                f"recording {where!r}: field {f.proto_name} holds {columns[f.name].size} values "
                f"for {n} frames; expected {size}"
            )
        columns[f.name] = columns[f.name].reshape(shape).astype(f.dtype, copy=False)
    t_ns = columns["t_ns"]
    if n and not (
        0 <= step[0] and step[-1] <= S.MAX_STEP and 0 <= t_ns.min() and t_ns.max() <= S.MAX_T_NS
    ):
        raise RecordingError(
            f"recording {where!r}: frame steps or times out of range (steps "
            f"{step[0]}..{step[-1]}); "
            f"expected steps 0..{S.MAX_STEP} and times 0..{S.MAX_T_NS} ns"
        )
    return FrameColumns(**columns)
