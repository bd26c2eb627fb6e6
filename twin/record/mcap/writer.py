"""McapRecorder: a sink that writes the twin's stream to MCAP, the recording's source of truth.

Per-step data goes out in blocks (one message per channel per 0.25 s of simulated time), the scene's
transforms at a viewing rate (30 Hz), events and commands in time order with the blocks. Every 0.5 s
of simulated time the chunk is closed and the file flushed, so a killed run loses at most that.
The file is written as `NAME.partial` beside its place (see twin.outputs) and renamed into place,
fsynced, when it is finalized: a run killed part-way never leaves a broken file where one was.
"""

from __future__ import annotations

import bisect
import itertools
import json
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Log_pb2 import Log
from mcap.writer import CompressionType

from twin.model import fields as F
from twin.model.columns import FIELD_NAMES, FrameColumns
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import CameraImage
from twin.model.json_values import finite_or_null
from twin.model.sink import Sink
from twin.model.types import Command, Event, Frame
from twin.record.mcap import schemas as S
from twin.record.mcap import wire
from twin.record.mcap.batch_writer import BatchWriter
from twin.record.mcap.blocks import BlockEncoder
from twin.record.mcap.metadata import check_run, portable_config, run_metadata
from twin.record.mcap.scene_tf import WORLD, SceneTransforms
from twin.record.outputs import Writeback, partial_path, publish
from twin.record.rows import FrameBatch

BLOCK_S = 0.25
FLUSH_S = 0.5
FLUSH_NS = round(FLUSH_S * 1e9)
GAP_NS = 2 * FLUSH_NS  # a run this long without a block (a high --rate) is flushed anyway
VIEW_HZ = 30.0
CHUNK_BYTES = 8 * 1024 * 1024  # chunks end at our flushes, not at a size
BATCH_FRAMES = 256  # on_frame hands its Frames to on_frames this many at a time at most
_WARNING = {"out_of_reach", "joint_limit", "settle_timeout", "suction_empty", "key_unknown"}
_ERROR = {"task_error", "break"}


def _json(value: object) -> bytes:
    """Standard JSON: a NaN or infinity (a diverged simulation's event data) is written as null,
    never as the NaN/Infinity tokens Python would write and other JSON readers refuse."""
    try:
        return json.dumps(
            value, sort_keys=True, separators=(",", ":"), default=_plain, allow_nan=False
        ).encode()
    except ValueError:
        return json.dumps(
            finite_or_null(value), sort_keys=True, separators=(",", ":"), default=_plain
        ).encode()


def _plain(value: object) -> object:
    """Twin.event already makes event data plain JSON; anything else here is a programming error."""
    raise TypeError(f"{type(value).__name__} value {value!r} is not JSON data")


COMPRESSIONS = {  # a chunk's compression by name
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


class McapRecorder(Sink):
    """Writes Frames, Commands and Events to an MCAP file; close() ends it cleanly (finalized
    marker)."""

    def __init__(
        self,
        path: str | Path,
        config: TwinConfig,
        run: dict,
        *,
        urdf: str,
        meshes: list[Path] = (),
        rate: int = 1,
        compression: str = "zstd",
        engine: dict[str, str] | None = None,
    ) -> None:
        if isinstance(rate, bool) or not isinstance(rate, int) or rate < 1:
            raise RecordingError(
                f"recording rate {rate!r} is invalid; expected a whole number of steps >= 1"
            )
        if compression not in COMPRESSIONS:
            raise RecordingError(
                f"chunk compression {compression!r} is unknown; expected one of "
                f"{sorted(COMPRESSIONS)}"
            )
        check_run(run)  # before the file is opened: bad input must not clobber an unfinished file
        mesh_files = _read_meshes(config, meshes)  # likewise an unreadable mesh
        self.path = Path(path)
        self.partial = partial_path(self.path)  # written here, renamed to path once finalized
        self.config = config
        self.rate = rate
        self.engine = dict(engine or {})  # the simulation's own versions, for twin.versions
        self.n_objects = len(config.objects)
        dt_ns = config.dt_ns
        self.block_frames = block_frames(dt_ns, rate)
        self.view_every = max(1, round(1e9 / (VIEW_HZ * dt_ns)))
        self.flush_ns = FLUSH_NS
        self._gap_ns = GAP_NS  # blocks this far apart (a high --rate): flush between
        self._tf = SceneTransforms(
            urdf, config.profile.joint_names, tuple(o.name for o in config.objects)
        )
        self._init_blocks(config)
        self._pending: list[tuple[int, int, bytes]] = []  # (log_time_ns, channel_id, data)
        self._last_step, self._last_t_ns = -1, 0  # the last frame seen
        # the last frame seen, when the recording rate left it out of the blocks (close writes it)
        self._last_left_out: FrameColumns | None = None
        self._last_written_step = -1
        self._last_flush_ns = 0
        self._set_due()
        self._sequence: dict[int, int] = {}
        self.frames_written = 0
        self._task_error = ""  # the first task_error it saw: such a run is never finalized as ok
        self.closed = False
        if self.path.is_dir():
            raise RecordingError(
                f"cannot write recording {str(self.path)!r}: it is a folder; expected an .mcap path"
            )
        try:
            self._file = open(self.partial, "wb")  # noqa: SIM115 - closed in close() or abandon()
        except OSError as err:
            raise RecordingError(
                f"cannot write recording {str(self.path)!r}: {err.strerror or err}"
            ) from err
        self._writer = BatchWriter(
            self._file, chunk_size=CHUNK_BYTES, compression=COMPRESSIONS[compression]
        )
        self._writeback = Writeback(self._file.fileno())
        try:
            self._start(config, run, urdf, mesh_files, compression)
        except BaseException:
            self._file.close()
            self.partial.unlink(missing_ok=True)  # nothing of the run in it yet
            raise

    def _init_blocks(self, config: TwinConfig) -> None:
        """The block encoder with the names its blocks carry, the next block's frames and the
        batch on_frame gathers."""
        self._joint_names = b"".join(wire.str_field(S.NAMES, n) for n in config.profile.joint_names)
        self._object_names = b"".join(wire.str_field(S.NAMES, o.name) for o in config.objects)
        n_joints = len(config.profile.joint_names)
        # the next block's frames (copied in: what on_frames gets may be written over after it),
        # and room for the run's last frame, which close adds whatever the rate
        self._block = FrameColumns.empty(self.block_frames + 1, n_joints, self.n_objects)
        self._block_count = 0
        self._blocks = BlockEncoder(
            {
                b: self._joint_names if b == "JointBlock" else self._object_names
                # every other block names the objects
                for b in F.BLOCKS
            },
        )
        # on_frame's Frames, gathered into columns for on_frames
        self._batch = FrameBatch(n_joints, self.n_objects, BATCH_FRAMES)

    def _start(
        self,
        config: TwinConfig,
        run: dict,
        urdf: str,
        mesh_files: list[tuple[str, str, bytes]],
        compression: str,
    ) -> None:
        self._writer.start(profile="", library=S.LIBRARY)
        self._channel: dict[str, int] = {}
        for spec in S.CHANNELS:
            schema_id = self._writer.register_schema(
                spec.schema_name, spec.schema_encoding, spec.schema_data()
            )
            self._channel[spec.topic] = self._writer.register_channel(
                spec.topic, spec.message_encoding, schema_id
            )
        self._tf_channel = self._channel[S.TF.topic]
        self._block_channels = [self._channel[S.BLOCK_TOPICS[b]] for b in F.BLOCKS]
        self._register_cameras(config)
        extra = {
            "rate_steps": str(self.rate),
            "block_frames": str(self.block_frames),
            "view_every_steps": str(self.view_every),
            "flush_s": repr(FLUSH_S),
            "compression": compression,
        }
        # a user URDF by its path relative to the recording: no absolute path in the file
        for name, record in run_metadata(
            portable_config(config, self.path), run, extra, self.engine
        ).items():
            self._writer.add_metadata(name, record)
        self._writer.add_attachment(0, 0, "robot.urdf", "application/xml", urdf.encode())
        for name, media_type, data in mesh_files:
            self._writer.add_attachment(0, 0, name, media_type, data)
        self._add(S.ROBOT_DESCRIPTION.topic, 0, _json({"data": urdf}))
        self._writer.flush()

    # -- sink -----------------------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        """One Frame, gathered with the ones before it; they go to on_frames when the batch is full
        or when this frame is one that makes the file grow (it fills a block, or ends a long gap
        without one), so the file is written when a Frame at a time would have written it."""
        frames = self._batch.add_frame(frame)
        if frames is None and (frame.step >= self._due_step or frame.t_ns >= self._due_ns):
            frames = self._batch.take()
        if frames is not None:
            self.on_frames(frames)

    def _take_batch(self) -> None:
        """The Frames on_frame has gathered, before anything that follows them in the stream."""
        frames = self._batch.take()
        if frames is not None:
            self.on_frames(frames)

    def on_frames(self, frames: FrameColumns) -> None:
        """Frames in time order (steps rising): each one's transforms at the viewing rate, its
        values into the block at the recording rate; a block is written when it is full, and the
        file flushed when blocks are far apart (a high --rate). What it keeps it copies."""
        n = len(frames)
        if not n:
            return
        viewed, kept = _every(frames.step, self.view_every), _every(frames.step, self.rate)
        transforms = self._transforms(frames, viewed)
        t_ns, t_end = frames.t_ns, int(frames.t_ns[-1])
        start, next_viewed, next_kept = 0, 0, 0
        while start < n:
            # the frame that fills the block, and the first from `start` on that ends a long gap
            # without a block (n: none of these frames)
            filling = next_kept + self.block_frames - self._block_count - 1
            fills = kept[filling] if filling < len(kept) else n
            gap_ns = self._last_flush_ns + self._gap_ns
            ends_gap = n if t_end < gap_ns else start + int(np.searchsorted(t_ns[start:], gap_ns))
            end = min(fills, ends_gap)
            stop = min(end + 1, n)
            took = bisect.bisect_left(viewed, stop, next_viewed)
            self._pending += transforms[next_viewed:took]
            next_viewed = took
            took = bisect.bisect_left(kept, stop, next_kept)
            block = self._keep(frames, kept[next_kept:took])
            next_kept = took
            if end == n:
                break
            if end == fills:
                self._write_block(block)
            else:
                self._write_pending()
                self._flush(int(t_ns[end]))
            start = end + 1
        self._last_step, self._last_t_ns = int(frames.step[-1]), t_end
        self._set_due()
        left_out = self._last_step % self.rate != 0
        self._last_left_out = frames.slice(n - 1, n).copy() if left_out else None

    def _transforms(self, frames: FrameColumns, viewed) -> list[tuple[int, int, bytes]]:
        """The scene transforms of frames[viewed], as pending /tf messages."""
        if not len(viewed):
            return []
        rows = _index(viewed)
        times = frames.t_ns[rows].tolist()
        joint_q = frames.joint_q[rows].tolist()
        pads = frames.pad_pose[rows].tolist()
        objects = frames.object_poses[rows].reshape(len(times), -1).tolist()
        return [
            (t, self._tf_channel, self._tf.message(t, q, pad + poses))
            for t, q, pad, poses in zip(times, joint_q, pads, objects, strict=True)
        ]

    def _keep(self, frames: FrameColumns, rows) -> FrameColumns:
        """Copy frames[rows] into the block; the block's columns (its first _block_count frames
        are its own)."""
        k, block = len(rows), self._block
        if k:
            which, at = _index(rows), self._block_count
            for name in FIELD_NAMES:
                getattr(block, name)[at : at + k] = getattr(frames, name)[which]
            self._block_count = at + k
        return block

    def _set_due(self) -> None:
        """The step of the frame that will fill the block, and the time that ends a long gap
        without a block (the frames that on_frame hands on at once)."""
        next_kept = (self._last_step // self.rate + 1) * self.rate
        self._due_step = next_kept + (self.block_frames - self._block_count - 1) * self.rate
        self._due_ns = self._last_flush_ns + self._gap_ns

    def on_command(self, command: Command) -> None:
        self._take_batch()
        body = _json({"step": command.step, "kind": command.kind, "args": command.args})
        self._pending.append(
            (command.step * self.config.dt_ns, self._channel[S.COMMANDS.topic], body)
        )

    def on_event(self, event: Event) -> None:
        self._take_batch()
        if event.kind == "task_error" and not self._task_error:
            self._task_error = event.message or "task error"
        full = _json(
            {
                "step": event.step,
                "t_ns": event.t_ns,
                "kind": event.kind,
                "body": event.body,
                "message": event.message,
                "data": event.data,
            }
        )
        self._pending.append((event.t_ns, self._channel[S.EVENTS.topic], full))
        self._pending.append((event.t_ns, self._channel[S.LOG.topic], _log_message(event)))

    def on_image(self, image: CameraImage) -> None:
        """A camera's picture as foxglove.CompressedImage, its calibration, and the camera's pose on
        /tf (world -> its frame_id), all at the picture's time."""
        self._take_batch()
        channels = self._camera_channels.get(image.camera)
        if channels is None:
            raise RecordingError(
                f"a picture from camera {image.camera!r}, which the configuration does not have; "
                f"expected one of {sorted(self._camera_channels)}"
            )
        spec = self._cameras[image.camera]
        picture = CompressedImage(frame_id=spec.frame_id, data=image.data, format=image.format)
        calibration = CameraCalibration(
            frame_id=spec.frame_id,
            width=spec.width_px,
            height=spec.height_px,
            distortion_model="plumb_bob",
            D=[0.0] * 5,
            K=spec.intrinsics(),
            R=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            P=spec.projection(),
        )
        pose = FrameTransforms()
        t = pose.transforms.add(parent_frame_id=WORLD, child_frame_id=spec.frame_id)
        t.translation.x, t.translation.y, t.translation.z = image.pose[:3]
        t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = image.pose[3:7]
        seconds, nanos = divmod(image.t_ns, 1_000_000_000)
        for message in (picture, calibration, t):
            message.timestamp.seconds, message.timestamp.nanos = seconds, nanos
        for channel_id, message in zip(
            (*channels, self._channel[S.TF.topic]), (picture, calibration, pose), strict=True
        ):
            self._pending.append(
                (image.t_ns, channel_id, message.SerializeToString(deterministic=True))
            )

    def _register_cameras(self, config: TwinConfig) -> None:
        """Each camera's image and calibration channels, after the fixed ones (none without
        cameras)."""
        self._cameras = {c.name: c for c in config.cameras}
        self._camera_channels: dict[str, tuple[int, int]] = {}
        if not config.cameras:
            return
        image_schema, calibration_schema = (
            self._writer.register_schema(spec.schema_name, spec.schema_encoding, spec.schema_data())
            for spec in (S.image_channel(""), S.calibration_channel(""))
        )
        for c in config.cameras:
            self._camera_channels[c.name] = (
                self._writer.register_channel(
                    S.image_channel(c.name).topic, "protobuf", image_schema
                ),
                self._writer.register_channel(
                    S.calibration_channel(c.name).topic, "protobuf", calibration_schema
                ),
            )

    # -- writing --------------------------------------------------------------------------------
    def _add(self, topic: str, t_ns: int, data: bytes) -> None:
        self._add_all([(t_ns, self._channel[topic], data)])

    def _add_all(self, items: list[tuple[int, int, bytes]]) -> None:
        """Messages given as (log_time_ns, channel_id, data), in order, each with its channel's
        next sequence number, in one call to the library (a call a message cost 3x as much)."""
        sequence, batch = self._sequence, []
        for t_ns, channel_id, data in items:
            # the readers refuse larger messages (a bound on damaged files)
            if len(data) > S.MAX_MESSAGE_BYTES:
                self._writer.add_messages(batch)  # those before it, as one by one
                raise RecordingError(
                    f"a message of {len(data):,} bytes exceeds the {S.MAX_MESSAGE_BYTES:,} a "
                    "recording may hold (a URDF or scene too large)"
                )
            seq = sequence.get(channel_id, 0)
            sequence[channel_id] = seq + 1
            batch.append((channel_id, t_ns, data, seq))
        self._writer.add_messages(batch)

    def _write_pending(self, then: list[tuple[int, int, bytes]] = ()) -> None:
        """The pending messages in time order, then `then`'s (a block's) as they come."""
        self._pending.sort(key=lambda item: item[0])  # stable: same-time items keep their order
        self._add_all([*self._pending, *then])
        self._pending.clear()

    def _write_block(self, block: FrameColumns) -> None:
        """The block's frames (its first _block_count) as one message per block channel
        (model.fields says which field goes where), after every message that comes before them."""
        n = self._block_count
        last_step, t_last = int(block.step[n - 1]), int(block.t_ns[n - 1])
        messages = self._blocks.messages(block, n)
        self.frames_written += n
        self._block_count = 0
        self._write_pending(
            [
                (t_last, channel_id, data)
                for channel_id, data in zip(self._block_channels, messages, strict=True)
            ]
        )
        self._last_written_step = last_step
        if t_last - self._last_flush_ns >= self.flush_ns:
            self._flush(t_last)

    def _flush(self, t_ns: int) -> None:
        """End the chunk and hand the file what is buffered (which the OS is asked now and then to
        start putting on disk: the close's fsync then has only the last chunks left to write)."""
        self._writer.flush()
        self._writeback.grew_to(self._file.tell())
        self._last_flush_ns = t_ns

    # -- ending ---------------------------------------------------------------------------------
    def abandon(self) -> None:
        """The run died without closing (its process was killed): write out what arrived, leave the
        .partial file without a summary or finalized marker, as a crash would (twin recover finds
        it)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._take_batch()
            if self._block_count:
                self._write_block(self._block)
            self._write_pending()
            self._writer.flush()
        finally:
            self._file.close()

    def close(self, outcome: str = "ok", error: str = "") -> None:
        """Write what is buffered (and the final frame, whatever the rate), the finalized marker,
        the summary; fsync the file and rename it into place. Idempotent. A run whose task raised is
        finalized as error even when its caller went on (twin check records a crashing task)."""
        if self.closed:
            return
        self.closed = True
        if outcome == "ok" and self._task_error:
            outcome, error = "error", self._task_error
        try:
            self._take_batch()
            if self._last_left_out is not None:  # the final frame, whatever the rate
                self._keep(self._last_left_out, range(1))
            if self._block_count:
                self._write_block(self._block)
            self._write_pending()
            self._writer.flush()
            self._writer.add_metadata(
                S.META_FINALIZED,
                {
                    "outcome": outcome,
                    "error": error,
                    "last_step": str(self._last_step),
                    "frames": str(self.frames_written),
                    "duration_ns": str(self._last_t_ns),
                },
            )
            self._writer.finish()
            self._file.close()
            publish(self.partial, self.path)
        except OSError as err:
            raise RecordingError(
                f"cannot finish recording {str(self.path)!r}: {err.strerror or err}"
            ) from err
        finally:
            self._file.close()


def block_frames(dt_ns: int, rate: int) -> int:
    """Frames kept per block: BLOCK_S of simulated time at the recording rate, at least one."""
    return max(1, round(BLOCK_S * 1e9 / (dt_ns * rate)))


def flush_steps(dt_ns: int, rate: int) -> Iterator[int]:
    """The steps of the frames at which a run's file grows (McapRecorder flushes its chunk), in
    order, for the twin's frames (every step from step 0): a block's last frame once FLUSH_S has
    passed since the last flush, or a frame GAP_NS past it while no block fills. The recorder
    process wakes its writer just after them (twin.record.process)."""
    per_block, last_flush_ns = block_frames(dt_ns, rate), 0
    for block in itertools.count(1):
        end_step = (block * per_block - 1) * rate  # the block's last kept frame
        while (gap_step := -(-(last_flush_ns + GAP_NS) // dt_ns)) < end_step:
            yield gap_step
            last_flush_ns = gap_step * dt_ns
        if end_step * dt_ns - last_flush_ns >= FLUSH_NS:
            yield end_step
            last_flush_ns = end_step * dt_ns


def _every(steps: np.ndarray, every: int) -> range | list[int]:
    """Which of the frames with these steps (rising) have a step that is a multiple of `every`: a
    range where the steps follow one another (the twin's frames), else a list."""
    first, n = int(steps[0]), len(steps)
    if int(steps[-1]) - first == n - 1:
        return range(-first % every, n, every)
    return np.flatnonzero(steps % every == 0).tolist()


def _index(rows: range | list[int]) -> slice | list[int]:
    """An index of numpy arrays for these rows: a slice (a view) where they are a range."""
    return slice(rows.start, rows.stop, rows.step) if isinstance(rows, range) else rows


def _log_message(event: Event) -> bytes:
    level = (
        Log.ERROR if event.kind in _ERROR else Log.WARNING if event.kind in _WARNING else Log.INFO
    )
    seconds, nanos = divmod(event.t_ns, 1_000_000_000)
    text = event.message or event.kind
    if event.data:
        text += " " + _json(event.data).decode()
    msg = Log(level=level, message=text, name=event.kind, file=event.body, line=0)
    msg.timestamp.seconds, msg.timestamp.nanos = seconds, nanos
    return msg.SerializeToString(deterministic=True)


def _read_meshes(config: TwinConfig, meshes: list[Path]) -> list[tuple[str, str, bytes]]:
    """(attachment name, media type, bytes) of each mesh file, read before the recording is
    opened."""
    out = []
    for mesh, name in _mesh_names(config, meshes):
        try:
            out.append((name, _media_type(mesh), mesh.read_bytes()))
        except OSError as err:
            raise RecordingError(
                f"cannot attach mesh {str(mesh)!r}: {err.strerror or err}"
            ) from err
    return out


def _mesh_names(config: TwinConfig, meshes: list[Path]) -> list[tuple[Path, str]]:
    """Attachment names for mesh files: their path relative to the URDF's folder (as the URDF names
    them, so attachments saved next to robot.urdf resolve), or the bare file name."""
    base = Path(config.profile.urdf_path).resolve().parent if config.profile.urdf_path else None
    out = []
    for mesh in meshes:
        mesh = Path(mesh)
        try:
            rel = mesh.resolve().relative_to(base).as_posix() if base else mesh.name
        except ValueError:
            rel = mesh.name
        out.append((mesh, rel))
    return out


def _media_type(path: Path) -> str:
    return {".stl": "model/stl", ".obj": "model/obj", ".dae": "model/vnd.collada+xml"}.get(
        os.path.splitext(str(path))[1].lower(), "application/octet-stream"
    )
