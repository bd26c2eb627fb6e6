"""Reading recordings: `load(path)` -> Recording (frames as numpy columns, commands, events, config).

One pass over the file's records (mcap.scan); the twin's blocks are decoded with a numpy fast
path (tests check it against the standard protobuf decoder). `scan(path, strict=False)` stops at
the first broken record instead of failing, which is what `twin recover` and `twin info` use.
"""

from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.records import Attachment, Channel, Footer, Header, Metadata, Schema

from twin.errors import RecordingError
from twin.model import fields as F
from twin.model.columns import FrameColumns
from twin.model.images import CameraTrack
from twin.model.recording import Recording
from twin.model.types import Command, Event
from twin.record.mcap import scan as mcap_scan
from twin.record.mcap import schemas as S
from twin.record.mcap import strict_json, wire
from twin.record.metadata import located_config, parse_config, parse_run

MAGIC = mcap_scan.MAGIC
Message = mcap_scan.Message


@dataclass
class Scan:
    """Every record read from a file, in file order, and whether the file ended cleanly."""

    path: str
    size_bytes: int
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[Attachment] = field(default_factory=list)
    library: str = ""
    header: bool = False  # an MCAP header record was read
    complete: bool = False  # the footer was reached
    problem: str = ""  # why reading stopped early

    def topic_of(self, message: Message) -> str:
        return self.channels[message.channel_id].topic

    def by_topic(self) -> dict[str, list[Message]]:
        out: dict[str, list[Message]] = {c.topic: [] for c in self.channels.values()}
        for m in self.messages:
            out[self.channels[m.channel_id].topic].append(m)
        return out


def block_steps(message: Message) -> np.ndarray:
    """The steps a block message (/twin/joints, /twin/suction, /twin/poses) holds."""
    return wire.array_of(wire.split_fields(message.data), S.STEP, "<i8")


def open_checked(path: str | Path) -> tuple[str, int]:
    """The path as text and its size; RecordingError for a missing, empty, non-file or non-MCAP path.
    Only a regular file is opened: a FIFO, socket or device would block or never end."""
    where = str(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise RecordingError(f"recording {where!r} does not exist") from None
    except (OSError, ValueError) as err:
        raise RecordingError(f"cannot read recording {where!r}: {getattr(err, 'strerror', None) or err}") from err
    if stat.S_ISDIR(mode):
        raise RecordingError(f"recording {where!r} is a directory; expected an MCAP file")
    if not stat.S_ISREG(mode):
        raise RecordingError(f"recording {where!r} is not a regular file (a FIFO, socket or device); expected an "
                             "MCAP file")
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
            raise RecordingError(f"recording {where!r} is truncated: {size} bytes, shorter than the MCAP magic")
        raise RecordingError(f"{where!r} is not an MCAP file (it does not start with the MCAP magic bytes)")
    return where, size


def scan(path: str | Path, *, strict: bool = True) -> Scan:
    """Read every record. strict: a file that ends without a footer or with a damaged record is a
    RecordingError; otherwise reading stops there and `problem` says why."""
    where, size = open_checked(path)
    out = Scan(where, size)
    footer = False
    with open(where, "rb") as f:
        try:
            for record in mcap_scan.records(f, size):
                kind = type(record)
                if kind is Message:
                    out.messages.append(record)
                elif kind is Channel:
                    out.channels[record.id] = record
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
        raise RecordingError(f"recording {where!r} is truncated or damaged: no complete MCAP header in its "
                             f"{size} bytes")
    if strict and not out.complete:
        raise RecordingError(
            f"recording {where!r} is truncated or damaged ({out.problem}) after {len(out.messages)} readable "
            f"messages; `twin recover {where} -o FIXED.mcap` restores its readable part")
    for m in out.messages:
        if m.channel_id not in out.channels:
            raise RecordingError(f"recording {where!r} has a message on unknown channel {m.channel_id}")
    return out


def load(path: str | Path) -> Recording:
    """A finalized (or recovered) recording, as a Recording."""
    return recording_from_scan(scan(path, strict=True))


def recording_from_scan(s: Scan) -> Recording:
    config = located_config(parse_config(s.metadata, repr(s.path)), s.path)
    topics = s.by_topic()
    frames = decode_frames(*(topics.get(t, []) for t in S.BLOCK_TOPICS.values()), len(config.objects), s.path)
    commands = [parse_command(m.data, s.path) for m in topics.get(S.COMMANDS.topic, [])]
    events = [parse_event(m.data, s.path) for m in topics.get(S.EVENTS.topic, [])]
    urdf = ""
    for m in topics.get(S.ROBOT_DESCRIPTION.topic, [])[:1]:
        urdf = _json_message(m.data, S.ROBOT_DESCRIPTION.topic, s.path).get("data")
        if not isinstance(urdf, str):
            raise RecordingError(f"recording {s.path!r}: the {S.ROBOT_DESCRIPTION.topic} message has no string "
                                 "'data'; expected {\"data\": URDF text}")
    meta = {name: dict(record) for name, record in sorted(s.metadata.items())
            if name not in (S.META_CONFIG, S.META_RUN)}
    return Recording(config=config, frames=frames, commands=commands, events=events,
                     run=parse_run(s.metadata, repr(s.path)), meta=meta,
                     finalized=S.META_FINALIZED in s.metadata and s.complete, urdf=urdf, path=s.path,
                     assets={a.name: a.data for a in s.attachments}, cameras=camera_tracks(config, topics, s.path))


def camera_tracks(config, topics: dict[str, list[Message]], where: str) -> dict[str, CameraTrack]:
    """Each configured camera's pictures from its foxglove.CompressedImage channel (bytes as stored,
    decoded only by CameraTrack.rgb); a picture's step is its time over the time step."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from google.protobuf.message import DecodeError

    tracks = {}
    for spec in config.cameras:
        topic = S.image_channel(spec.name).topic
        steps, times, data = [], [], []
        for m in topics.get(topic, []):
            picture = CompressedImage()
            try:
                picture.ParseFromString(m.data)
            except DecodeError as err:
                raise RecordingError(f"recording {where!r}: a {topic} message is not a CompressedImage: {err}") from err
            t_ns = picture.timestamp.seconds * 1_000_000_000 + picture.timestamp.nanos
            if picture.format != spec.format or t_ns % config.dt_ns or not 0 <= t_ns <= S.MAX_T_NS:
                raise RecordingError(f"recording {where!r}: a {topic} picture at {t_ns} ns in {picture.format!r}; "
                                     f"expected {spec.format!r} at a whole step of {config.dt_ns} ns")
            steps.append(t_ns // config.dt_ns)
            times.append(t_ns)
            data.append(picture.data)
        tracks[spec.name] = CameraTrack(spec.name, spec.width_px, spec.height_px, spec.format,
                                        np.array(steps, dtype=np.int64), np.array(times, dtype=np.int64), data)
    return tracks


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
        raise ValueError(f"{name} {value!r:.40} is not a whole number 0..{limit}")
    return value


def _text(v: dict, name: str) -> str:
    value = v.get(name)
    if not isinstance(value, str):
        raise TypeError(f"{name} {value!r:.40} is not a string")
    return value


def _object(v: dict, name: str) -> dict:
    value = v.get(name)
    if not isinstance(value, dict):
        raise TypeError(f"{name} {value!r:.40} is not a JSON object")
    return value


def parse_command(data: bytes, where: str) -> Command:
    """A /commands message: step (0..MAX_STEP), kind, args; finite numbers only (the args themselves are
    checked by Twin.apply when replayed). RecordingError naming the field otherwise."""
    v = _json_message(data, "command", where)
    try:
        return Command(step=_whole(v, "step", S.MAX_STEP), kind=_text(v, "kind"), args=_object(v, "args"))
    except (TypeError, ValueError) as err:
        raise RecordingError(f"recording {where!r}: malformed command {json.dumps(v)[:120]}: {err}") from err


def parse_event(data: bytes, where: str) -> Event:
    """A /twin/events message: step, t_ns, kind, body, message, data; RecordingError naming the field otherwise."""
    v = _json_message(data, "event", where)
    try:
        return Event(step=_whole(v, "step", S.MAX_STEP), t_ns=_whole(v, "t_ns", S.MAX_T_NS), kind=_text(v, "kind"),
                     body=_text(v, "body"), message=_text(v, "message"), data=_object(v, "data"))
    except (TypeError, ValueError) as err:
        raise RecordingError(f"recording {where!r}: malformed event {json.dumps(v)[:120]}: {err}") from err


def _columns(messages: list[Message], spec: list[tuple[int, str]], where: str, topic: str) -> list[np.ndarray]:
    """Concatenate the numbered fields of every block on a channel into flat arrays."""
    parts: list[list[bytes]] = [[] for _ in spec]
    for m in messages:
        try:
            fields = wire.split_fields(m.data)
        except RecordingError as err:
            raise RecordingError(f"recording {where!r}: a {topic} block is malformed: {err}") from err
        for i, (number, dtype) in enumerate(spec):
            parts[i].append(wire.raw_of(fields, number, dtype))
    out = []
    for p, (_, dtype) in zip(parts, spec, strict=True):
        raw = b"".join(p)
        if len(raw) % np.dtype(dtype).itemsize:
            raise RecordingError(f"recording {where!r}: a {topic} field is not a whole number of {dtype} values")
        out.append(np.frombuffer(raw, dtype=dtype).copy())
    return out


def decode_frames(joints: list[Message], suction: list[Message], poses: list[Message], n_objects: int,
                  where: str) -> FrameColumns:
    """FrameColumns from the three block channels (model.fields says which field is where); RecordingError
    if they disagree."""
    n_joints = 4
    columns: dict[str, np.ndarray] = {}
    steps = []
    for (block, topic), messages in zip(S.BLOCK_TOPICS.items(), (joints, suction, poses), strict=True):
        fields = [f for f in F.block_fields(block) if f.name == "step" or f.name not in columns]
        arrays = _columns(messages, [(f.number, f.wire) for f in fields], where, topic)
        for f, array in zip(fields, arrays, strict=True):
            if f.name == "step":
                steps.append(array)
            else:
                columns[f.name] = array
    step = columns["step"] = steps[0]
    n = len(step)
    if not all(np.array_equal(step, other) for other in steps[1:]):
        raise RecordingError(f"recording {where!r}: the joint, suction and pose channels cover different steps "
                             f"({', '.join(str(len(s)) for s in steps)} frames)")
    if n > 1 and not np.all(np.diff(step) > 0):
        raise RecordingError(f"recording {where!r}: frame steps are not increasing")
    for f in F.FRAME_FIELDS:
        shape = (n, *f.trailing(n_joints, n_objects))
        size = int(np.prod(shape, dtype=np.int64))
        if columns[f.name].size != size:
            raise RecordingError(f"recording {where!r}: field {f.proto_name} holds {columns[f.name].size} values "
                                 f"for {n} frames; expected {size}")
        columns[f.name] = columns[f.name].reshape(shape).astype(f.dtype, copy=False)
    t_ns = columns["t_ns"]
    if n and not (0 <= step[0] and step[-1] <= S.MAX_STEP and 0 <= t_ns.min() and t_ns.max() <= S.MAX_T_NS):
        raise RecordingError(f"recording {where!r}: frame steps or times out of range (steps {step[0]}..{step[-1]}); "
                             f"expected steps 0..{S.MAX_STEP} and times 0..{S.MAX_T_NS} ns")
    return FrameColumns(**columns)
