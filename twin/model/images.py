"""Cameras: where a camera sits and what it sees (CameraSpec), one rendered picture (CameraImage,
what sinks get through on_image) and all of one camera's pictures in a recording (CameraTrack).

A camera is part of the scene's configuration (TwinConfig.cameras), so a replay renders it again.
Pictures are stored encoded and decoded only when asked, by the codec (twin.pictures.track_rgb,
which checks a picture's header against the camera first).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from twin.model.errors import ConfigError
from twin.model.quat import quat_from_axes, rotate

FORMATS = ("png", "jpeg")
# eye and target in world axes, or in the pad tip's frame (x along its heading, z up)
MOUNTS = ("world", "pad")
DEFAULT_SIZE_PX = (320, 240)
DEFAULT_RATE_HZ = 15.0
MAX_SIDE_PX = 4096
CAMERA_FRAME_PREFIX = "camera_"  # a camera's frame_id in /tf: the prefix, then its name


@dataclass(frozen=True)
class CameraSpec:
    """A pinhole camera: image size, rate in simulated time, vertical field of view, clip planes,
    and its eye, target and up direction, in world axes (mount "world") or in the pad tip's frame
    (mount "pad": it moves and turns with the pad)."""

    name: str
    width_px: int = DEFAULT_SIZE_PX[0]
    height_px: int = DEFAULT_SIZE_PX[1]
    rate_hz: float = DEFAULT_RATE_HZ
    fov_deg: float = 60.0
    near_m: float = 0.02
    far_m: float = 5.0
    mount: str = "world"
    eye_m: tuple[float, float, float] = (0.0, 0.075, 1.6)
    target_m: tuple[float, float, float] = (0.0, 0.075, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    format: str = "png"

    def __post_init__(self) -> None:
        if not self.name or not all(c.isalnum() or c in "_-" for c in self.name):
            raise ConfigError(
                f"camera name {self.name!r} is invalid; expected letters, digits, '_' or '-'"
            )
        for side in (self.width_px, self.height_px):
            if isinstance(side, bool) or not isinstance(side, int) or not 16 <= side <= MAX_SIDE_PX:
                raise ConfigError(
                    f"camera {self.name!r} size {self.width_px}x{self.height_px} is invalid; "
                    f"expected whole numbers of pixels 16..{MAX_SIDE_PX}"
                )
        if not (math.isfinite(self.rate_hz) and 0.1 <= self.rate_hz <= 1000):
            raise ConfigError(
                f"camera {self.name!r} rate {self.rate_hz} Hz is invalid; expected 0.1..1000 Hz"
            )
        if self.mount not in MOUNTS:
            raise ConfigError(
                f"camera {self.name!r} mount {self.mount!r} is invalid; expected one of {MOUNTS}"
            )
        if self.format not in FORMATS:
            raise ConfigError(
                f"camera {self.name!r} format {self.format!r} is invalid; expected one of {FORMATS}"
            )
        if not (0 < self.near_m < self.far_m and 1 <= self.fov_deg <= 170):
            raise ConfigError(
                f"camera {self.name!r}: near {self.near_m} m, far {self.far_m} m, field of view "
                f"{self.fov_deg} deg; expected 0 < near < far and 1..170 deg"
            )

    def every_steps(self, dt_ns: int) -> int:
        """Every how many physics steps this camera takes a picture (step 0 always)."""
        return max(1, round(1e9 / (self.rate_hz * dt_ns)))

    def focal_px(self) -> float:
        """Focal length in pixels (square pixels), from the vertical field of view."""
        return 0.5 * self.height_px / math.tan(math.radians(self.fov_deg) / 2)

    def intrinsics(self) -> tuple[float, ...]:
        """The 3x3 camera matrix K, row-major (fx 0 cx, 0 fy cy, 0 0 1)."""
        f = self.focal_px()
        return (f, 0.0, self.width_px / 2, 0.0, f, self.height_px / 2, 0.0, 0.0, 1.0)

    def projection(self) -> tuple[float, ...]:
        """The 3x4 projection matrix P of this undistorted camera (K and a zero fourth column),
        row-major."""
        k = self.intrinsics()
        return (*k[0:3], 0.0, *k[3:6], 0.0, *k[6:9], 0.0)

    @property
    def frame_id(self) -> str:
        """The camera's coordinate frame in MCAP (/tf) and Foxglove."""
        return f"{CAMERA_FRAME_PREFIX}{self.name}"


# The built-in cameras. overhead: straight down on the workspace (robot base, pick point (0.2, 0.7)
# and place point (-0.3, -0.55) of pick_place), image up = +y. wrist: on the pad, 3 cm above its tip
# and 6 cm behind it, looking down at what the pad picks.
CAMERAS = {
    "overhead": CameraSpec("overhead"),
    "wrist": CameraSpec(
        "wrist",
        mount="pad",
        fov_deg=75.0,
        near_m=0.01,
        far_m=2.0,
        eye_m=(-0.06, 0.0, 0.03),
        target_m=(0.0, 0.0, -0.05),
        up=(1.0, 0.0, 0.0),
    ),
}


def camera(
    name: str, size_px: tuple[int, int] = DEFAULT_SIZE_PX, rate_hz: float = DEFAULT_RATE_HZ
) -> CameraSpec:
    """A built-in camera by name, at this size and rate."""
    if name not in CAMERAS:
        raise ConfigError(f"unknown camera {name!r}; expected one of {', '.join(CAMERAS)}")
    return replace(
        CAMERAS[name], width_px=int(size_px[0]), height_px=int(size_px[1]), rate_hz=float(rate_hz)
    )


def camera_view(spec: CameraSpec, pad_pose: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
    """The camera's eye, target and up in world axes for a frame whose pad tip pose is pad_pose
    (x, y, z, qx, qy, qz, qw); a "world" camera ignores it."""
    if spec.mount == "world":
        return spec.eye_m, spec.target_m, spec.up
    origin, turn = pad_pose[:3], pad_pose[3:7]
    eye, target = (
        tuple(o + v for o, v in zip(origin, rotate(turn, p), strict=True))
        for p in (spec.eye_m, spec.target_m)
    )
    return eye, target, rotate(turn, spec.up)


def optical_pose(
    eye: tuple[float, ...], target: tuple[float, ...], up: tuple[float, ...]
) -> tuple[float, ...]:
    """The camera's optical frame in world axes as (x, y, z, qx, qy, qz, qw): z looks at the target,
    x to the image's right, y down the image (the convention of Foxglove's CameraCalibration)."""
    forward = _unit(tuple(t - e for t, e in zip(target, eye, strict=True)))
    right = _unit(_cross(forward, up))
    down = _cross(forward, right)
    return (*eye, *quat_from_axes(right, down, forward))


def _cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(v: tuple[float, ...]) -> tuple[float, float, float]:
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n)


class CameraImage(NamedTuple):
    """One picture, as sinks get it (Sink.on_image): the camera, the step and time it shows, the
    encoding ("png" or "jpeg"), the encoded bytes, and where the camera was (optical_pose)."""

    camera: str
    step: int
    t_ns: int
    format: str
    data: bytes
    pose: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


@dataclass
class CameraTrack:
    """All pictures of one camera in a recording, in step order; data[i] shows step[i] (at t_ns[i]),
    taken from pose[i] (x, y, z, qx, qy, qz, qw: the camera's /tf in the file; empty when a file
    holds none). source: the file they were read from ("" in memory), named when a picture is
    bad."""

    name: str
    width_px: int
    height_px: int
    format: str
    step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    t_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    data: list[bytes] = field(default_factory=list)
    source: str = ""
    pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 7), dtype=np.float64))

    def __len__(self) -> int:
        return len(self.data)

    @staticmethod
    def from_images(spec: CameraSpec, images: list[CameraImage]) -> CameraTrack:
        return CameraTrack(
            name=spec.name,
            width_px=spec.width_px,
            height_px=spec.height_px,
            format=spec.format,
            step=np.array([im.step for im in images], dtype=np.int64),
            t_ns=np.array([im.t_ns for im in images], dtype=np.int64),
            data=[im.data for im in images],
            pose=np.array([im.pose for im in images], dtype=np.float64).reshape(-1, 7),
        )


def tracks(cameras: tuple[CameraSpec, ...], images: list[CameraImage]) -> dict[str, CameraTrack]:
    """Each camera's pictures among images (in the order they came), as tracks by camera name."""
    return {
        spec.name: CameraTrack.from_images(spec, [im for im in images if im.camera == spec.name])
        for spec in cameras
    }
