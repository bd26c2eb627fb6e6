"""pick_place that looks before it picks: before each pick the overhead camera takes a picture and
the task finds the box in it, picks the box where it lies with the pad turned to the box's yaw, and
places it at the target (yaw 0). pick_place picks at a fixed point and misses a box a few
millimetres off; this one is limited by what the camera sees and what the arm reaches.

The picture: PyBullet's segmentation mask and depth buffer, drawn by the CPU renderer in a world of
its own posed from the current frame (twin.sim.camera.RenderWorld: it never touches the physics).
The box's pixels (the mask) are lifted to 3-D with the depth, the camera's K and pose; the pixels
within TOP_BAND_M of the highest are its top face, whose centre is the pick point and whose
four-fold moment gives its yaw (a square's yaw is known modulo 90 degrees). The top's height over
the floor (z = 0) is the box's measured height.

The part of the picture the decision used (the mask and depth in a window around the box, the
window's place, K and the camera's pose) goes into the `seen` event, so the recording holds it and
`locate(SeenPicture.from_event(data))` re-derives the same pick from the file alone; a replay says
that event again at the same step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.errors import TaskError
from twin.model.images import CAMERAS, CameraSpec, camera_view, optical_pose
from twin.model.quat import rotate
from twin.model.types import NO_BODY
from twin.tasks.pick_place import (
    MAX_ERROR_M,
    POINT_A_M,
    POINT_B_M,
    SAFE_POINT_M,
    Z_JOINT,
    _lower_until_held,
    mm_beyond,
)

FLOOR_Z_M = 0.0  # the floor's top (twin.sim.world builds it so)
TOP_BAND_M = 0.004  # pixels this close below the highest are the box's top face
WINDOW_MARGIN_PX = 2  # the window kept in the event: the box's pixels and this many around them
MIN_TOP_PIXELS = 4  # fewer top-face pixels than this: not enough to place the box
PICTURE_WIDTH_PX = (
    640  # the task's picture: the overhead camera's view at 640x480 (3.85 mm a pixel on the floor)
)


@dataclass(frozen=True)
class SeenPicture:
    """What the decision uses: the window (u0, v0 its top-left pixel) of the mask (the box's pixels)
    and of the depth (metres along the optical axis), the picture's K and the camera's optical pose
    (x, y, z, qx, qy, qz, qw; x right, y down, z forward)."""

    u0: int
    v0: int
    mask: np.ndarray  # (h, w) bool
    depth_m: np.ndarray  # (h, w) float64
    k: tuple[float, ...]
    pose: tuple[float, ...]

    def to_event(self) -> dict:
        return {
            "window_px": [self.u0, self.v0, int(self.mask.shape[1]), int(self.mask.shape[0])],
            "mask": ["".join("1" if m else "0" for m in row) for row in self.mask.tolist()],
            "depth_m": self.depth_m.tolist(),
            "k": list(self.k),
            "camera_pose": list(self.pose),
        }

    @staticmethod
    def from_event(data: dict) -> SeenPicture:
        u0, v0, _, _ = data["window_px"]
        mask = np.array([[c == "1" for c in row] for row in data["mask"]], dtype=bool).reshape(
            len(data["mask"]), -1
        )
        return SeenPicture(
            u0=int(u0),
            v0=int(v0),
            mask=mask,
            depth_m=np.array(data["depth_m"], dtype=np.float64).reshape(mask.shape),
            k=tuple(data["k"]),
            pose=tuple(data["camera_pose"]),
        )


@dataclass(frozen=True)
class Located:
    """Where the box is: its top face's centre (x, y), yaw (rad, in (-45, 45] degrees), the top's
    height over the floor, and how many top-face pixels that rests on."""

    x_m: float
    y_m: float
    yaw_rad: float
    height_m: float
    pixels: int


def locate(seen: SeenPicture) -> Located | None:
    """The box in the picture, or None when too little of its top face is in view."""
    fx, _, cx, _, fy, cy = seen.k[:6]
    v, u = np.nonzero(seen.mask)
    if len(u) == 0:
        return None
    z = seen.depth_m[v, u]
    # PyBullet's tiny renderer samples a pixel at its corner in OpenGL's bottom-up rows: in the
    # picture's top-down pixels that is (u, v + 1), not the centre (u + 0.5, v + 0.5)
    cam = np.stack([(u + seen.u0 - cx) / fx * z, (v + seen.v0 + 1.0 - cy) / fy * z, z], axis=1)
    axes = np.array(
        [rotate(seen.pose[3:7], e) for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
    )
    world = cam @ axes + np.array(seen.pose[:3])
    top = world[world[:, 2] >= world[:, 2].max() - TOP_BAND_M]
    if len(top) < MIN_TOP_PIXELS:
        return None
    x, y = float(top[:, 0].mean()), float(top[:, 1].mean())
    moment = np.sum(
        (top[:, 0] - x + 1j * (top[:, 1] - y)) ** 4
    )  # a square's is real and negative at yaw 0
    yaw = float(np.angle(-moment)) / 4.0
    return Located(x, y, yaw, float(top[:, 2].mean()) - FLOOR_Z_M, len(top))


class Eye:
    """The task's camera: the overhead camera's pose and field of view, at PICTURE_WIDTH_PX, drawing
    the box's mask and the depth in a render world of the run's scene."""

    def __init__(self, twin, width_px: int = PICTURE_WIDTH_PX) -> None:
        from twin.sim.camera import RenderWorld

        base = CAMERAS["overhead"]
        height_px = round(width_px * base.height_px / base.width_px)
        self.spec = CameraSpec(
            "overhead",
            width_px=width_px,
            height_px=height_px,
            fov_deg=base.fov_deg,
            near_m=base.near_m,
            far_m=base.far_m,
            eye_m=base.eye_m,
            target_m=base.target_m,
            up=base.up,
        )
        self.world = RenderWorld(twin.config)

    def look(self, frame, box_index: int) -> SeenPicture | None:
        """The picture of this frame, cut to a window around the box (None when it is not in
        view)."""
        s = self.spec
        self.world.pose(frame)
        eye, target, up = camera_view(s, frame.pad_pose)
        depth_m, objects = self.world.depth_and_objects(s, (eye, target, up))
        mask = objects == box_index
        rows, cols = np.nonzero(mask)
        if len(rows) == 0:
            return None
        v0, u0 = max(0, rows.min() - WINDOW_MARGIN_PX), max(0, cols.min() - WINDOW_MARGIN_PX)
        v1, u1 = rows.max() + WINDOW_MARGIN_PX + 1, cols.max() + WINDOW_MARGIN_PX + 1
        return SeenPicture(
            u0=int(u0),
            v0=int(v0),
            mask=mask[v0:v1, u0:u1],
            depth_m=depth_m[v0:v1, u0:u1],
            k=s.intrinsics(),
            pose=optical_pose(eye, target, up),
        )

    def close(self) -> None:
        self.world.close()


def run(
    twin,
    cycles: int = 2,
    pause_s: float = 0.5,
    box: str = "box",
    keep_going: bool = False,
    max_error_m: float = MAX_ERROR_M,
    picture_px: int = PICTURE_WIDTH_PX,
) -> None:
    """Each cycle looks, picks the box where it lies and places it on the other point; see the
    module docstring. A box the camera cannot find, or one out of the arm's reach, fails the
    cycle."""
    if isinstance(cycles, bool) or not isinstance(cycles, int) or cycles < 1:
        raise ValueError(f"cycles {cycles!r} is invalid; expected an integer >= 1")
    box_index = twin.object_index(box)
    eye = Eye(twin, picture_px)
    try:
        twin.phase("safe pose")
        twin.suction(False)
        twin.raise_()
        twin.move_to(*SAFE_POINT_M, heading_rad=0.0)
        for cycle in range(1, cycles + 1):
            place = POINT_B_M if cycle % 2 else POINT_A_M
            _cycle(twin=twin, eye=eye, cycle=cycle, place=place, box=box, box_index=box_index, pause_s=pause_s, keep_going=keep_going, max_error_m=max_error_m)
    finally:
        eye.close()


def _cycle(
    twin,
    eye: Eye,
    cycle: int,
    place: tuple[float, float],
    box: str,
    box_index: int,
    pause_s: float,
    keep_going: bool,
    max_error_m: float,
) -> None:
    """One cycle: look, pick what was seen, place it; a miss is an error or, with keep_going, an
    event."""
    found = _look(twin, eye, cycle, box, box_index)
    if found is None:
        return _miss(
            twin,
            keep_going,
            cycle,
            box,
            f"cycle {cycle}: {box!r} not found in the overhead picture",
        )
    hold_z, miss = _pick(twin, found, cycle, box_index, pause_s)
    if miss:
        return _miss(twin, keep_going, cycle, box, miss)
    miss = _place(
        twin,
        cycle=cycle,
        place=place,
        box=box,
        box_index=box_index,
        hold_z=hold_z,
        pause_s=pause_s,
        max_error_m=max_error_m,
    )
    if miss:
        _miss(twin, keep_going, cycle, box, miss)
    return None


def _look(twin, eye: Eye, cycle: int, box: str, box_index: int) -> Located | None:
    """The arm out of the way, a picture, the box located in it; a `seen` event either way."""
    twin.phase(f"cycle {cycle}: look")
    twin.move_to(*SAFE_POINT_M)  # the arm out of the way of the picture
    seen = eye.look(twin.frame, box_index)
    found = None if seen is None else locate(seen)
    if found is None:
        twin.event(
            "seen",
            box,
            f"cycle {cycle}: {box!r} not in view",
            cycle=cycle,
            found=False,
            **({} if seen is None else seen.to_event()),
        )
        return None
    twin.event(
        "seen",
        box,
        f"cycle {cycle}: {box!r} at ({found.x_m:.4f}, {found.y_m:.4f}) m, yaw "
        f"{math.degrees(found.yaw_rad):.2f} deg",
        cycle=cycle,
        found=True,
        x_m=found.x_m,
        y_m=found.y_m,
        yaw_rad=found.yaw_rad,
        height_m=found.height_m,
        pixels=found.pixels,
        **seen.to_event(),
    )
    return found


def _pick(
    twin, found: Located, cycle: int, box_index: int, pause_s: float
) -> tuple[float, str]:
    """Down on the box where it was seen, at its yaw, and up with it held: (the Z target where it
    took hold, ""), else (nan, why not) with the pad off and raised."""
    twin.phase(f"cycle {cycle}: pick at ({found.x_m:.4f}, {found.y_m:.4f})")
    twin.move_to(found.x_m, found.y_m, heading_rad=found.yaw_rad)
    twin.wait(pause_s)
    twin.suction(True)
    hold_z, took_hold = _lower_until_held(twin)
    twin.wait(pause_s)
    held = twin.frame.held_body
    if held != box_index:
        twin.suction(False)
        twin.raise_()
        what = (
            "the hold broke"
            if took_hold
            else "nothing sensed"
            if held == NO_BODY
            else "held another body"
        )
        return math.nan, (
            f"cycle {cycle}: suction on at the box seen at "
            f"({found.x_m:.4f}, {found.y_m:.4f}), {what}"
        )
    twin.raise_()
    return hold_z, ""


def _place(
    twin,
    cycle: int,
    place: tuple[float, float],
    box: str,
    box_index: int,
    hold_z: float,
    pause_s: float,
    max_error_m: float,
) -> str:
    """The held box set down square at place, at the height it was taken at; a `placed` event
    with its error. "" when placed within max_error_m, else why not."""
    twin.phase(f"cycle {cycle}: place at {place}")
    twin.move_to(
        *place, heading_rad=0.0
    )  # the pad holds the box at the yaw it was picked with: placed square
    twin.set_joint_target(Z_JOINT, hold_z)
    twin.settle()
    if twin.frame.held_body != box_index:
        twin.suction(False)
        twin.raise_()
        return f"cycle {cycle}: {box!r} was lost on the way to {place}"
    twin.suction(False)
    twin.wait(pause_s)
    twin.raise_()
    pose = twin.object_pose(box)
    error_m = math.hypot(pose[0] - place[0], pose[1] - place[1])
    yaw_rad = 2.0 * math.atan2(pose[5], pose[6])
    twin.event(
        "placed",
        box,
        f"cycle {cycle}: placed {error_m * 1000:.3f} mm from {place}",
        cycle=cycle,
        target_m=list(place),
        error_m=error_m,
        yaw_rad=yaw_rad,
    )
    if error_m > max_error_m:
        return (
            f"cycle {cycle}: placed {mm_beyond(error_m, max_error_m)} mm "
            f"from {place}, beyond {max_error_m * 1000:g} mm"
        )
    return ""
def _miss(twin, keep_going: bool, cycle: int, box: str, message: str) -> None:
    if not keep_going:
        raise TaskError(message)
    twin.event("cycle_failed", box, message, cycle=cycle)
