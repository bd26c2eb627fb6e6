"""The suction pad: CoppeliaSim's stock model as a per-step rule over the World.

While on and empty, the first object the downward ray sensor sees is fixed to the pad; switching
off releases it; with finite strength the hold breaks on pull, shear or peel beyond the limits.
Like CoppeliaSim's ray proximity sensor, which detects a shape's back faces too, the sensor also
sees an object its ray starts inside (a pad set into a box with sim.setJointPosition, as report
000's keys do); PyBullet's rayTest does not report a body the ray starts in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from twin.model.config import SuctionParams
from twin.model.quat import rotate
from twin.model.types import NO_BODY, Frame
from twin.sim.world import World

REACH_MARGIN_M = 0.01  # beyond an object's half-diagonal, where _may_sense still casts the ray


@dataclass(frozen=True)
class SuctionEvent:
    kind: str
    body: int
    message: str


class Suction:
    def __init__(self, params: SuctionParams, pad_length_m: float, world: World,
                 object_sizes_m: tuple[tuple[float, float, float], ...]) -> None:
        self.params = params
        self.world = world
        self.pad_length_m = pad_length_m
        self.object_half_m = tuple((sx / 2, sy / 2, sz / 2) for sx, sy, sz in object_sizes_m)
        # each object's bounding sphere (its half-diagonal), widened by a margin for the engine's
        # ray tolerance: a sensor ray outside every sphere cannot sense anything (_may_sense)
        self._reach_m = tuple(
            math.sqrt(hx * hx + hy * hy + hz * hz) + REACH_MARGIN_M
            for hx, hy, hz in self.object_half_m
        )
        self.on = False
        self.sensed = NO_BODY
        self.held = NO_BODY
        self._held_this_period = False
        self._broken_this_period = False  # a broken hold stays broken until the pad is switched off
        self.idle_on: bool | None = False  # the `on` for which update() changes nothing (_idle_on)

    def update(
        self, on: bool, frame: Frame, heading_of: Callable[[Frame], float]
    ) -> list[SuctionEvent]:
        """Advance the pad's state for the coming step from the latest Frame; returns what happened.
        The sensor ray is cast only while the pad is on and empty (what it sees otherwise cannot
        matter). heading_of(frame): the pad's heading (rad), asked for only when an object is
        attached."""
        p = self.params
        # holding on: nothing changes
        if on and self.on and self.held != NO_BODY and p.infinite_strength:
            self.sensed = self.held
            return []
        if not on and not self.on:
            return []
        events: list[SuctionEvent] = []
        x, y, z_tip = frame.pad_pose[:3]
        root_z = z_tip + self.pad_length_m
        if on and self.held == NO_BODY:
            z_from = root_z - p.sensor_offset_m
            self.sensed = NO_BODY
            if self._may_sense(frame, x, y, z_from):
                self.sensed = self.world.ray_down(x, y, z_from, p.sensor_range_m)
                if self.sensed == NO_BODY:
                    self.sensed = self._inside(frame, (x, y, z_from))
        else:
            self.sensed = self.held if on else NO_BODY
        if on and not self.on:
            self._held_this_period = False
            self._broken_this_period = False
        if not on and self.on and self.held == NO_BODY and not self._held_this_period:
            events.append(SuctionEvent("suction_empty", NO_BODY, "suction on, nothing sensed"))
        self.on = on
        if self.held != NO_BODY and not on:
            events.append(self._drop("release", "suction off"))
        elif self.held != NO_BODY and not p.infinite_strength:
            reason = self._overload(frame)
            if reason:
                events.append(self._drop("break", reason))
                self._broken_this_period = True
        if on and self.held == NO_BODY and self.sensed != NO_BODY and not self._broken_this_period:
            self.world.attach(self.sensed, (x, y, root_z), heading_of(frame))
            self.held = self.sensed
            self._held_this_period = True
            events.append(SuctionEvent("attach", self.held, "suction attached"))
        self.idle_on = self._idle_on()
        return events

    def _idle_on(self) -> bool | None:
        """The one `on` that leaves the pad as it is: False while it is off, True while it holds on
        with infinite strength (sensed stays held), else None. The twin calls update() only for
        another `on` (pick_place: 198 calls instead of 1495 in 2517 steps)."""
        if not self.on:
            return False
        return True if self.held != NO_BODY and self.params.infinite_strength else None

    def _may_sense(self, frame: Frame, x: float, y: float, z_from: float) -> bool:
        """False when the sensor's ray (straight down from (x, y, z_from), sensor_range_m long)
        stays outside every object's bounding sphere: then neither the engine's ray nor _inside can
        find one, and both are skipped (pick_place: 196 ray tests in 2517 steps became 32). A
        point of the ray within a sphere of radius r about (cx, cy, cz) is within r of it in x-y
        and in z."""
        z_to = z_from - self.params.sensor_range_m
        for r, pose in zip(self._reach_m, frame.object_poses):
            dx, dy, cz = x - pose[0], y - pose[1], pose[2]
            if dx * dx + dy * dy <= r * r and z_to - r <= cz <= z_from + r:
                return True
        return False

    def _inside(self, frame: Frame, point: tuple[float, float, float]) -> int:
        """The first scene object (a box) whose volume holds point, or NO_BODY."""
        for i, (half, pose) in enumerate(zip(self.object_half_m, frame.object_poses, strict=True)):
            conj = (-pose[3], -pose[4], -pose[5], pose[6])
            local = rotate(conj, (point[0] - pose[0], point[1] - pose[1], point[2] - pose[2]))
            if all(abs(c) <= h for c, h in zip(local, half, strict=True)):
                return i
        return NO_BODY

    def _drop(self, kind: str, why: str) -> SuctionEvent:
        body = self.held
        self.world.detach()
        self.held = NO_BODY
        return SuctionEvent(kind, body, why)

    def _overload(self, frame: Frame) -> str:
        """Why the hold must break now (pull, shear or peel over its limit), or ''.

        The pad points down (-z, a SCARA never tilts it). Pull is the force drawing the object away
        from the cup (the pad's upward force on it; pressing the object down is not pull), shear the
        sideways force, peel the torque about x and y taken at the cup's face (the pad tip)."""
        p = self.params
        # nothing stepped since
        (fx, fy, fz), (tx, ty, _tz) = frame.hold_force_n, frame.hold_torque_nm
        cx, cy, cz = frame.object_poses[self.held][:3]
        tip = frame.pad_pose
        rx, ry, rz = cx - tip[0], cy - tip[1], cz - tip[2]  # tip -> object's centre of mass
        peel_x, peel_y = tx + ry * fz - rz * fy, ty + rz * fx - rx * fz
        pull_n, shear_n, peel_nm = fz, math.hypot(fx, fy), math.hypot(peel_x, peel_y)
        if pull_n > p.max_pull_force_n:
            return f"pull {pull_n:.3f} N > max_pull_force {p.max_pull_force_n} N"
        if shear_n > p.max_shear_force_n:
            return f"shear {shear_n:.3f} N > max_shear_force {p.max_shear_force_n} N"
        if peel_nm > p.max_peel_torque_nm:
            return f"peel torque {peel_nm:.4f} N·m > max_peel_torque {p.max_peel_torque_nm} N·m"
        return ""
