"""Rendering the configuration's cameras: a sink that, at each camera's steps, draws the frame with
PyBullet's CPU renderer (ER_TINY_RENDERER) and hands the picture to the other sinks (on_image).

The pictures are drawn in a world of their own (a DIRECT client holding the robot and the scene's
objects, never stepped), posed from the frame's joint positions and object poses: rendering never
touches the physics of the run, so a run with cameras moves exactly as one without, and the same
frames give the same pixels. The floor is left out of that world: it fills the picture and cost 12 of
the 15.6 ms a 320x240 picture took; the renderer's background stands for it.
"""

from __future__ import annotations

import numpy as np

from twin.model.config import TwinConfig
from twin.model.images import CameraImage, CameraSpec, camera_view, encode, optical_pose
from twin.model.sink import Sink
from twin.model.types import Frame
from twin.sim.world import World, pb


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

    def render(self, spec: CameraSpec, eye: tuple[float, ...], target: tuple[float, ...],
               up: tuple[float, ...]) -> np.ndarray:
        """The scene as this camera sees it: (height, width, 3) uint8."""
        view = pb.computeViewMatrix(eye, target, up)
        projection = pb.computeProjectionMatrixFOV(spec.fov_deg, spec.width_px / spec.height_px, spec.near_m, spec.far_m)
        _, _, rgba, _, _ = pb.getCameraImage(spec.width_px, spec.height_px, view, projection,
                                             renderer=pb.ER_TINY_RENDERER, flags=pb.ER_NO_SEGMENTATION_MASK,
                                             physicsClientId=self.client)
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (spec.height_px, spec.width_px, 4))[:, :, :3]


def render_frame(world: RenderWorld, cameras: tuple[CameraSpec, ...], frame: Frame) -> list[CameraImage]:
    """Pictures of one frame from each of these cameras, encoded."""
    world.pose(frame)
    out = []
    for spec in cameras:
        eye, target, up = camera_view(spec, frame.pad_pose)
        pixels = world.render(spec, eye, target, up)
        out.append(CameraImage(spec.name, frame.step, frame.t_ns, spec.format, encode(pixels, spec.format),
                               optical_pose(eye, target, up)))
    return out


class CameraRenderer(Sink):
    """Renders every camera of config at its steps and passes the pictures to targets (a list the
    twin owns: sinks added to it later get them too; the renderer skips itself)."""

    def __init__(self, config: TwinConfig, targets: list[Sink]) -> None:
        self.cameras = config.cameras
        self.targets = targets
        self._every = tuple(c.every_steps(config.dt_ns) for c in config.cameras)
        self._world = RenderWorld(config)

    def on_frame(self, frame: Frame) -> None:
        due = tuple(c for c, every in zip(self.cameras, self._every, strict=True) if frame.step % every == 0)
        if not due:
            return
        for image in render_frame(self._world, due, frame):
            for sink in self.targets:
                if sink is not self:
                    sink.on_image(image)

    def close(self, outcome: str = "ok", error: str = "") -> None:
        self._world.close()
