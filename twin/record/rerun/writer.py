"""The Rerun sink: a run drawn as an .rrd file (robot from its URDF, boxes, pad, joint plots,
events).

Frames come in as columns (on_frames: the recorder process's ring, a loaded recording; on_frame
gathers the twin's single Frames into columns first) and are copied into preallocated numpy
buffers; every `batch_steps` frames (and at close) the buffers go out as columns with
`send_columns` — one `rr.log` per step would slow a run ~20x — built straight as Arrow arrays
(twin.record.rerun.columns).
The output (a file, or any stream the caller opened) is chosen apart from the logging code. A file
is written as `NAME.partial` and renamed into place, fsynced, at close (see twin.outputs).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Self

import numpy as np
import pyarrow as pa
import rerun as rr

from twin.model.columns import FIELD_SPECS, FrameColumns
from twin.model.config import TwinConfig
from twin.model.errors import RecordingError
from twin.model.images import CameraImage
from twin.model.recording import Recording
from twin.model.sink import Sink
from twin.model.types import Command, Event, Frame
from twin.record.images import recorded_images
from twin.record.outputs import Writeback, check_target, partial_path, publish
from twin.record.rerun import scene
from twin.record.rerun.columns import ColumnMaker
from twin.record.rerun.joints import JointMotion
from twin.record.rows import FrameBatch
from twin.robot.urdf import urdf_text as profile_urdf_text

# A batch is 16 sends, and each has a cost whatever its length: the SDK's (~0.1 ms of its Python,
# and its threads' encoding of a chunk) and the columns' (twin.record.rerun.columns). The writer's
# process CPU per frame, fed a 16-cycle run at once, was 4.5-4.6 us at 2048 frames, 1.9-3.6 at
# 4096 and 1.9-2.9 at 8192 (3 runs each, 2026-11-29; at 8192, 3.7-4.3 before the columns were
# built straight as Arrow).
DEFAULT_BATCH_STEPS = 8192
GATHER_FRAMES = 256  # on_frame hands the twin's Frames to on_frames this many at a time


def file_stream(path: str | os.PathLike, config: TwinConfig) -> rr.RecordingStream:
    """A recording stream of its own that saves to `path` (with the twin's default blueprint)."""
    target = check_target(path, "recording", "a .rrd file path", error=RecordingError)
    stream = rr.RecordingStream(scene.APPLICATION_ID)
    stream.save(target, default_blueprint=scene.blueprint(config))
    return stream


def finish_file(stream: rr.RecordingStream, partial: Path, target: Path) -> None:
    """Flush and close a stream saving to `partial`, then put the finished file in place as
    `target`."""
    stream.flush()
    stream.disconnect()  # closes the file sink: the .rrd is complete on disk
    try:
        publish(partial, target)
    except OSError as err:
        raise RecordingError(f"cannot finish {str(target)!r}: {err.strerror or err}") from err


class _Buffers:
    """Preallocated columns (dtypes and shapes from model.fields) for the frames of one batch: the
    fields the view draws."""

    DRAWN = (
        "step",
        "t_ns",
        "joint_q",
        "joint_target",
        "suction_on",
        "held_body",
        "pad_pose",
        "object_poses",
    )

    def __init__(self, capacity: int, n_objects: int) -> None:
        for name in self.DRAWN:
            dtype, shape = FIELD_SPECS[name]
            setattr(self, name, np.empty((capacity, *shape(4, n_objects)), dtype=dtype))


class RerunRecorder(Sink):
    """A sink (on_frame/on_command/on_event) that writes what it receives to a Rerun recording."""

    def __init__(
        self,
        path: str | os.PathLike,
        config: TwinConfig,
        urdf_text: str,
        *,
        batch_steps: int = DEFAULT_BATCH_STEPS,
    ) -> None:
        # bad input fails before a file is created
        tree = self._prepare(config, urdf_text, batch_steps)
        target = check_target(path, "recording", "a .rrd file path", error=RecordingError)
        self.path = str(path)
        self._start(file_stream(partial_path(target), config), tree)
        # the file the SDK writes, opened again to have the OS start writing it out as it grows
        self._writeback = _writeback_of(partial_path(target))

    @classmethod
    def to_stream(
        cls,
        stream: rr.RecordingStream,
        config: TwinConfig,
        urdf_text: str,
        *,
        batch_steps: int = DEFAULT_BATCH_STEPS,
    ) -> Self:
        """Log into a stream the caller opened (saved, served or spawned); the caller sends the
        blueprint."""
        self = cls.__new__(cls)
        tree = self._prepare(config, urdf_text, batch_steps)
        self.path = ""
        self._start(stream, tree)
        self._writeback = None
        return self

    def _prepare(self, config: TwinConfig, urdf_text: str, batch_steps: int) -> rr.urdf.UrdfTree:
        if isinstance(batch_steps, bool) or not isinstance(batch_steps, int) or batch_steps < 1:
            raise RecordingError(
                f"batch size {batch_steps!r} is invalid; expected an integer >= 1 steps"
            )
        self.config = config
        self.batch_steps = batch_steps
        tree = scene.load_urdf_tree(config, urdf_text)
        self._joints = [
            JointMotion.from_urdf_joint(j) for j in scene.driven_joints(config, urdf_text)
        ]
        # Frame names repeat in every row (see _send_frames): built once as Arrow arrays, sliced per
        # batch.
        self._frame_names = [
            (
                pa.array([j.parent_frame] * batch_steps, pa.utf8()),
                pa.array([j.child_frame] * batch_steps, pa.utf8()),
            )
            for j in self._joints
        ]
        self._object_paths = [scene.object_path(o.name) for o in config.objects]
        self._make = ColumnMaker(batch_steps, scene.PAD_RGBS)
        self._buf = _Buffers(batch_steps, len(config.objects))
        # on_frame's Frames, gathered into columns for on_frames
        self._batch = FrameBatch(
            len(config.profile.joint_names), len(config.objects), GATHER_FRAMES
        )
        self._n = 0
        self._events: list[Event] = []
        self._commands: list[Command] = []
        self.frames_written = 0
        self.closed = False
        return tree

    def _start(self, stream: rr.RecordingStream, tree: rr.urdf.UrdfTree) -> None:
        self.stream = stream
        scene.log_static_scene(stream, self.config, tree)

    # -- sink ---------------------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        frames = self._batch.add_frame(frame)
        if frames is not None:
            self.on_frames(frames)

    def on_frames(self, frames: FrameColumns) -> None:
        """Frames as columns, sliced into the buffers the batches are sent from."""
        start, total = 0, len(frames)
        while start < total:
            k = min(self.batch_steps - self._n, total - start)
            i, b = self._n, self._buf
            for name in _Buffers.DRAWN:
                getattr(b, name)[i : i + k] = getattr(frames, name)[start : start + k]
            self._n += k
            start += k
            if self._n == self.batch_steps:
                self._send_batch()
        if self._writeback is not None:  # what the SDK has written of the batches sent
            self._writeback.grew_to(os.fstat(self._writeback.fd).st_size)

    def on_image(self, image: CameraImage) -> None:
        """A camera's picture on its entity (world/cameras/NAME, under its static Pinhole), with the
        camera's pose at that moment: shown in the camera's own view and as a frustum in the 3D
        view."""
        times = _event_times([image.step], [image.t_ns])
        path = scene.camera_path(image.camera)
        self.stream.send_columns(
            path,
            indexes=times,
            columns=rr.EncodedImage.columns(
                blob=[image.data], media_type=[f"image/{image.format}"]
            ),
        )
        self.stream.send_columns(
            path,
            indexes=times,
            columns=rr.Transform3D.columns(
                translation=[image.pose[:3]], quaternion=[image.pose[3:7]]
            ),
        )

    def on_command(self, command: Command) -> None:
        self._commands.append(command)

    def on_event(self, event: Event) -> None:
        self._events.append(event)

    def close(self, outcome: str = "ok", error: str = "") -> None:
        """Send what is buffered and finish the file (fsynced and renamed into place); the view
        keeps no outcome (the MCAP file's finalized record does)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._send_buffered()
            if self.path:
                finish_file(self.stream, partial_path(self.path), Path(self.path))
            else:
                self.stream.flush()
        finally:
            self._close_writeback()

    def abandon(self) -> None:
        """The run died without closing: write out what arrived but leave the file as
        `NAME.partial`, so an earlier file at the path is not replaced by a cut-short view."""
        if self.closed:
            return
        self.closed = True
        try:
            self._send_buffered()
            self.stream.flush()
            if self.path:
                self.stream.disconnect()
        finally:
            self._close_writeback()

    def _close_writeback(self) -> None:
        if self._writeback is not None:
            os.close(self._writeback.fd)
            self._writeback = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- batches ------------------------------------------------------------------------------
    def _send_buffered(self) -> None:
        """Everything not yet sent: the frames of the open batch, the events, the commands."""
        frames = self._batch.take()
        if frames is not None:
            self.on_frames(frames)
        self._send_batch()

    def _send_batch(self) -> None:
        """The frames gathered, and the events and commands that came since the last batch: they
        go with each batch, not all at the close, which the twin waits for."""
        self._send_frames()
        self._send_events()
        self._send_commands()

    def _send_frames(self) -> None:
        n = self._n
        if n == 0:
            return
        b = self._buf
        # Fresh buffers for the next batch: the arrays just sent may still be referenced by the SDK.
        self._buf = _Buffers(self.batch_steps, len(self._object_paths))
        self._n = 0
        self.frames_written += n
        times = [
            rr.TimeColumn(scene.STEP_TIMELINE, sequence=b.step[:n]),
            rr.TimeColumn(scene.TIME_TIMELINE, duration=b.t_ns[:n].astype("timedelta64[ns]")),
        ]
        send, make = self.stream.send_columns, self._make
        for j, joint in enumerate(self._joints):
            # Frame names go in every row: the viewer does not join a static frame name to timed
            # poses.
            columns = make.transforms(*joint.transforms(b.joint_q[:n, j]), self._frame_names[j])
            send(scene.joint_path(joint.name), indexes=times, columns=columns)
        for k, path in enumerate(self._object_paths):
            poses = b.object_poses[:n, k]
            send(path, indexes=times, columns=make.transforms(poses[:, :3], poses[:, 3:]))
        sleeve_centres = b.pad_pose[:n, :3] + [0.0, 0.0, 0.5 * self.config.profile.pad_length_m]
        colors = scene.pad_color_index(b.suction_on[:n], b.held_body[:n])
        send(scene.PAD_PATH, indexes=times, columns=make.cylinders(sleeve_centres, colors))
        for j, role in enumerate(scene.ROLES):
            base = scene.Z_PATH if role == "z" else scene.ANGLES_PATH
            send(f"{base}/{role}", indexes=times, columns=make.scalars(b.joint_q[:n, j]))
            send(
                f"{base}/{role}_target", indexes=times, columns=make.scalars(b.joint_target[:n, j])
            )
        send(f"{scene.SUCTION_PATH}/on", indexes=times, columns=make.scalars(b.suction_on[:n]))
        send(
            f"{scene.SUCTION_PATH}/holding",
            indexes=times,
            columns=make.scalars(b.held_body[:n] >= 0),
        )

    def _send_events(self) -> None:
        events, self._events = self._events, []
        if not events:
            return
        events.sort(key=lambda e: e.step)
        texts = [" ".join(part for part in (e.kind, e.body, e.message) if part) for e in events]
        self.stream.send_columns(
            scene.EVENTS_PATH,
            indexes=_event_times([e.step for e in events], [e.t_ns for e in events]),
            columns=rr.TextLog.columns(
                text=texts, level=[scene.EVENT_LEVELS.get(e.kind, "INFO") for e in events]
            ),
        )

    def _send_commands(self) -> None:
        commands, self._commands = self._commands, []
        if not commands:
            return
        commands.sort(key=lambda c: c.step)
        texts = [
            f"{c.kind} " + " ".join(f"{k}={c.args[k]!r}" for k in sorted(c.args)) for c in commands
        ]
        steps = [c.step for c in commands]
        self.stream.send_columns(
            scene.COMMANDS_PATH,
            indexes=_event_times(steps, [s * self.config.dt_ns for s in steps]),
            columns=rr.TextLog.columns(text=texts, level=["DEBUG"] * len(texts)),
        )


def _writeback_of(path: Path) -> Writeback | None:
    """The Writeback of the file at `path`, through a read-only descriptor of its own, or None if
    it cannot be opened (the writeback is then left to the close's fsync)."""
    try:
        return Writeback(os.open(path, os.O_RDONLY))
    except OSError:
        return None


def _event_times(steps: list[int], t_ns: list[int]) -> list[rr.TimeColumn]:
    return [
        rr.TimeColumn(scene.STEP_TIMELINE, sequence=np.asarray(steps, dtype=np.int64)),
        rr.TimeColumn(
            scene.TIME_TIMELINE, duration=np.asarray(t_ns, dtype=np.int64).astype("timedelta64[ns]")
        ),
    ]


def write_rrd(
    recording: Recording, path: str | os.PathLike, *, batch_steps: int = DEFAULT_BATCH_STEPS
) -> int:
    """Draw a loaded recording (e.g. an MCAP file) as an .rrd through the same sink; returns frames
    written."""
    urdf = recording.urdf or profile_urdf_text(recording.config.profile)
    with RerunRecorder(path, recording.config, urdf, batch_steps=batch_steps) as recorder:
        recorder.on_frames(recording.frames)
        for command in recording.commands:
            recorder.on_command(command)
        for event in recording.events:
            recorder.on_event(event)
        for image in recorded_images(
            recording.config.cameras,
            recording.cameras,
            recording.frames.step,
            recording.frames.pad_pose,
        ):
            recorder.on_image(image)
    return recorder.frames_written
