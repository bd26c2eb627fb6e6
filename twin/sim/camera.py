"""Rendering the configuration's cameras: at each camera's steps the twin's frame is drawn with
PyBullet's CPU renderer (ER_TINY_RENDERER) and the picture handed back to the twin, which passes it
to its sinks (on_image).

The pictures are drawn in a world of their own (a DIRECT client holding the robot and the scene's
objects, never stepped), posed from the frame's joint positions and object poses: rendering never
touches the physics of the run, so a run with cameras moves exactly as one without, and the same
frames give the same pixels. The floor is left out of that world: it fills the picture and cost
most of a picture's render time; the renderer's background stands for it.
"""

from __future__ import annotations

import collections
import marshal
import multiprocessing
import os
from collections.abc import Callable

import numpy as np

from twin.helpers import start_helper
from twin.model.config import TwinConfig
from twin.model.errors import HelperError
from twin.model.images import CameraImage, CameraSpec, camera_view, optical_pose
from twin.model.types import NO_BODY, Frame
from twin.pictures import encode
from twin.sim.world import World, pb

_View = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]  # eye, target, up


class RenderWorld(World):
    """The robot and the scene's objects (no floor), posed by hand for each picture."""

    def build(self) -> None:
        pb.resetSimulation(physicsClientId=self.client)
        self._load_robot()
        self.object_ids = tuple(self._create_object(o) for o in self.config.objects)

    def pose(self, frame: Frame) -> None:
        """Put the joints and objects where the frame has them."""
        c = self.client
        for joint, q in zip(self.joints, frame.joint_q, strict=True):
            pb.resetJointState(self.robot, joint, q, 0.0, physicsClientId=c)
        for body, pose in zip(self.object_ids, frame.object_poses, strict=True):
            pb.resetBasePositionAndOrientation(body, pose[:3], pose[3:7], physicsClientId=c)

    def _draw(self, spec: CameraSpec, view: _View, flags: int) -> tuple:
        """PyBullet's CPU renderer at this camera's size and lens: rgba, depth buffer, segments."""
        eye, target, up = view
        projection = pb.computeProjectionMatrixFOV(
            spec.fov_deg, spec.width_px / spec.height_px, spec.near_m, spec.far_m
        )
        _, _, rgba, depth, segments = pb.getCameraImage(
            spec.width_px,
            spec.height_px,
            pb.computeViewMatrix(eye, target, up),
            projection,
            renderer=pb.ER_TINY_RENDERER,
            flags=flags,
            physicsClientId=self.client,
        )
        return rgba, depth, segments

    def render(
        self,
        spec: CameraSpec,
        eye: tuple[float, ...],
        target: tuple[float, ...],
        up: tuple[float, ...],
    ) -> np.ndarray:
        """The scene as this camera sees it: (height, width, 3) uint8."""
        rgba = self._draw(spec, (eye, target, up), pb.ER_NO_SEGMENTATION_MASK)[0]
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (spec.height_px, spec.width_px, 4))[
            :, :, :3
        ]

    def depth_and_objects(self, spec: CameraSpec, view: _View) -> tuple[np.ndarray, np.ndarray]:
        """What a depth camera with a segmentation mask sees from `view` (eye, target, up): the
        depth in metres along the optical axis at each pixel (OpenGL's depth buffer, linearized
        with the camera's near and far planes) and the index of the scene object seen there
        (NO_BODY where none is), each (height, width)."""
        _, buffer, segments = self._draw(spec, view, 0)
        shape = (spec.height_px, spec.width_px)
        buffer = np.reshape(np.asarray(buffer, dtype=np.float64), shape)
        depth_m = spec.far_m * spec.near_m / (spec.far_m - (spec.far_m - spec.near_m) * buffer)
        segments = np.reshape(np.asarray(segments), shape)
        objects = np.full(shape, NO_BODY, dtype=np.int32)
        for index, body in enumerate(self.object_ids):
            objects[segments == body] = index
        return depth_m, objects


def render_frame(
    world: RenderWorld, cameras: tuple[CameraSpec, ...], frame: Frame
) -> list[CameraImage]:
    """Pictures of one frame from each of these cameras, encoded."""
    world.pose(frame)
    out = []
    for spec in cameras:
        eye, target, up = camera_view(spec, frame.pad_pose)
        pixels = world.render(spec, eye, target, up)
        out.append(
            CameraImage(
                camera=spec.name,
                step=frame.step,
                t_ns=frame.t_ns,
                format=spec.format,
                data=encode(pixels, spec.format),
                pose=optical_pose(eye, target, up),
            )
        )
    return out


class CameraRenderer:
    """Renders every camera of config at the frames it is shown (on_frame) and hands each picture to
    hand_on (the twin's fan-out to its sinks).

    background (the default, unless this process is a daemon, which may not fork: a worker of a
    pool): the pictures are drawn in a render process of their own (forked, with its own render
    world), so the stepping goes on while they are drawn. Either way a frame's pictures are handed
    on when the pictures of LAG_PICTURES later camera frames have been asked for (or at flush and
    close): always at the same point of the run, drawn here or there, so the files are
    byte-identical."""

    def __init__(
        self,
        config: TwinConfig,
        hand_on: Callable[[CameraImage], None],
        *,
        background: bool | None = None,
    ) -> None:
        self.cameras = config.cameras
        self._hand_on = hand_on
        self._every = tuple(c.every_steps(config.dt_ns) for c in config.cameras)
        if background is None:
            background = not multiprocessing.current_process().daemon
        self._world: RenderWorld | None = None
        self._process: _RenderProcess | None = None
        # drawn here, not yet handed on
        self._drawn: collections.deque[list[CameraImage]] = collections.deque()
        if background:
            self._process = _RenderProcess(config)
        else:
            self._world = RenderWorld(config)

    @property
    def pending(self) -> int:
        """Camera frames asked for whose pictures are not handed on yet."""
        return self._process.pending if self._process is not None else len(self._drawn)

    def on_frame(self, frame: Frame) -> None:
        due = tuple(
            c for c, every in zip(self.cameras, self._every, strict=True) if frame.step % every == 0
        )
        if not due:
            return
        if self._process is not None:
            self._process.send(due, frame)
        else:
            self._drawn.append(render_frame(self._world, due, frame))
        if self.pending > LAG_PICTURES:
            self._emit_next()

    def _emit_next(self) -> None:
        images = self._process.receive() if self._process is not None else self._drawn.popleft()
        for image in images:
            self._hand_on(image)

    def flush(self) -> None:
        """Hand on the pictures not handed on yet (before the recorders close: a run's last
        pictures)."""
        while self.pending:
            self._emit_next()

    def close(self) -> None:
        """Hand on the pictures not handed on yet, then end the render process (or world)."""
        try:
            self.flush()
        finally:
            if self._process is not None:
                self._process.close()
                self._process = None
            if self._world is not None:
                self._world.close()
                self._world = None


# camera frames in flight: enough to keep the render process busy while the twin steps
LAG_PICTURES = 4
_CLOSE = b"C"
_FAILED = b"!"


class _RenderProcess:
    """A forked child with its own render world: gets (cameras, frame), answers with the
    pictures."""

    def __init__(self, config: TwinConfig) -> None:
        self.pending = 0
        self._conn, self._process = start_helper(self, _render_loop, (config,), name="twin-render")

    def send(self, cameras: tuple[CameraSpec, ...], frame: Frame) -> None:
        try:
            self._conn.send_bytes(marshal.dumps((tuple(c.name for c in cameras), tuple(frame))))
        except OSError as err:
            raise HelperError(f"the camera render process stopped: {err}") from err
        self.pending += 1

    def receive(self) -> list[CameraImage]:
        try:
            reply = self._conn.recv_bytes()
        except (EOFError, OSError) as err:
            raise HelperError(
                f"the camera render process stopped (exit code {self._process.exitcode})"
            ) from err
        self.pending -= 1
        if reply.startswith(_FAILED):
            raise HelperError(f"rendering a camera failed: {reply[1:].decode(errors='replace')}")
        return [CameraImage(*item) for item in marshal.loads(reply)]

    def close(self) -> None:
        try:
            self._conn.send_bytes(_CLOSE)
        except OSError:
            pass
        self._conn.close()
        self._process.join(timeout=10)


def _render_loop(conn, config: TwinConfig) -> None:
    """The render process (twin.helpers): draw each frame it is sent with the cameras named, until
    told to close or the twin's end of the pipe closes."""
    specs = {c.name: c for c in config.cameras}
    world = RenderWorld(config)
    while True:
        try:
            message = conn.recv_bytes()
        except (EOFError, OSError):
            os._exit(0)
        if message == _CLOSE:
            os._exit(0)
        try:
            names, fields = marshal.loads(message)
            images = render_frame(world, tuple(specs[n] for n in names), Frame._make(fields))
            reply = marshal.dumps([tuple(im) for im in images])
        except Exception as err:  # noqa: BLE001 - told to the twin as one line
            reply = _FAILED + f"{type(err).__name__}: {err}".encode()
        try:
            conn.send_bytes(reply)
        except OSError:
            os._exit(0)
