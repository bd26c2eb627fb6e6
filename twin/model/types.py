"""The stream the twin produces: Frame (every physics step), Command (every input), Event.

Units are SI and named: joint values are rad for revolute joints and m for the prismatic joint;
poses are (x_m, y_m, z_m, qx, qy, qz, qw); time is integer nanoseconds of simulated time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

Pose = tuple[float, float, float, float, float, float, float]
NO_BODY = -1


class Frame(NamedTuple):
    """The state after `step` physics steps (step 0 is the initial state).

    A NamedTuple rather than a dataclass: one is built every physics step, and this is the
    cheapest immutable record Python offers."""

    step: int
    t_ns: int
    joint_q: tuple[float, ...]  # per joint, in profile joint order (rad | m)
    joint_qd: tuple[float, ...]  # rad/s | m/s
    joint_effort: tuple[float, ...]  # applied motor torque/force, N·m | N
    joint_target: tuple[float, ...]  # motor target, rad | m
    suction_on: bool
    sensed_body: int  # index into the scene's objects, NO_BODY when nothing is sensed
    held_body: int  # index into the scene's objects, NO_BODY when nothing is held
    # the pad's force on the held object, world frame (hanging: +m·g z)
    hold_force_n: tuple[float, float, float]
    # the pad's torque on it about its centre of mass, world frame
    hold_torque_nm: tuple[float, float, float]
    # the pad tip (centre of the cup's face), world frame; None in the Frames a sink that does not
    # read it is handed while no other sink does (Sink.reads_pad_pose)
    pad_pose: Pose | None
    object_poses: tuple[Pose, ...]  # per scene object, in scene order


# Each Command kind and its arguments (the Twin applies these; a recording's JSON Schema names them)
COMMAND_ARGS: dict[str, tuple[str, ...]] = {
    "joint_target": ("joint", "q"),
    "joint_position": ("joint", "q"),
    "joint_max_velocity": ("joint", "v"),
    "signal": ("name", "value"),
    "key": ("key",),
    "event": ("kind", "body", "message", "data"),  # what a task or client said
}


@dataclass(frozen=True, slots=True)
class Command:
    """An input, applied before the physics step that starts at `step`.

    kind: joint_target {joint, q}, joint_position {joint, q}, joint_max_velocity {joint, v},
    signal {name, value|None}, key {key}.
    """

    step: int
    kind: str
    args: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Event:
    """A discrete happening: attach, release, break, suction_empty, out_of_reach, joint_limit,
    phase, placed, task_error, log, ..."""

    step: int
    t_ns: int
    kind: str
    body: str = ""  # object name, when the event concerns one
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)
