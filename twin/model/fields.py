"""The one description of a Frame's fields: from it come the numpy columns (model.columns), the MCAP
block messages and their encoding and decoding (record.mcap), and the fields that runs are compared
and toleranced by (compare). Adding a field means adding it here, then in the five places that spell
the table out by hand for readers, type checkers or speed (model.types.Frame, model.columns.
FrameColumns, record.rows.FrameRows.pack_into, record.tables' column stems, and the Frame the twin
builds from World.state); tests/model/test_frame_table.py fails until all five agree.

Order matters: it is the order of the columns, of each block message's fields, of the report's rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A field's trailing shape, given the robot's joints and the scene's objects.
SHAPES = {
    "frame": lambda n_joints, n_objects: (),
    "joint": lambda n_joints, n_objects: (n_joints,),
    "xyz": lambda n_joints, n_objects: (3,),
    "pose": lambda n_joints, n_objects: (7,),  # x, y, z (m), qx, qy, qz, qw
    "object_pose": lambda n_joints, n_objects: (n_objects, 7),
}


@dataclass(frozen=True)
class Compared:
    """How one comparison field reads a Frame field: `name` (channel.field), the components it takes
    (a slice of the last axis, or all), the metric (compare.metrics), unit and what it measures."""

    name: str
    components: slice | None
    metric: str  # joint | abs | discrete | norm | angle
    unit: str
    what: str


@dataclass(frozen=True)
class FrameField:
    """One Frame field: its column dtype and shape, where it travels in MCAP (block message, field
    name and number, packed encoding) and how runs are compared on it."""

    name: str  # the Frame attribute and the FrameColumns column
    dtype: type
    shape: str  # a key of SHAPES
    # "JointBlock" | "SuctionBlock" | "PoseBlock"; "*" for step and t_ns, which every block has
    block: str
    proto_name: str
    number: int  # protobuf field number (3 is each block's names field)
    wire: str  # packed encoding: "<f8", "<i8", "<i4", "|u1"
    compared: tuple[Compared, ...] = ()

    def trailing(self, n_joints: int, n_objects: int) -> tuple[int, ...]:
        return SHAPES[self.shape](n_joints, n_objects)


_POSITION, _ORIENTATION = slice(0, 3), slice(3, 7)
FRAME_FIELDS: tuple[FrameField, ...] = (
    FrameField("step", np.int64, "frame", "*", "step", 1, "<i8"),
    FrameField("t_ns", np.int64, "frame", "*", "t_ns", 2, "<i8"),
    FrameField(
        "joint_q",
        np.float64,
        "joint",
        "JointBlock",
        "position",
        4,
        "<f8",
        (Compared("joints.position", None, "joint", "rad|m", "joint angle (wrapped) or Z travel"),),
    ),
    FrameField(
        "joint_qd",
        np.float64,
        "joint",
        "JointBlock",
        "velocity",
        5,
        "<f8",
        (Compared("joints.velocity", None, "abs", "rad/s|m/s", "joint velocity"),),
    ),
    FrameField(
        "joint_effort",
        np.float64,
        "joint",
        "JointBlock",
        "effort",
        6,
        "<f8",
        (Compared("joints.effort", None, "abs", "N·m|N", "motor torque or force"),),
    ),
    FrameField(
        "joint_target",
        np.float64,
        "joint",
        "JointBlock",
        "target",
        7,
        "<f8",
        (Compared("joints.target", None, "joint", "rad|m", "motor target (wrapped)"),),
    ),
    FrameField(
        "suction_on",
        np.bool_,
        "frame",
        "SuctionBlock",
        "on",
        4,
        "|u1",
        (Compared("suction.on", None, "discrete", "", "pad switched on (exact or off)"),),
    ),
    FrameField(
        "sensed_body",
        np.int32,
        "frame",
        "SuctionBlock",
        "sensed_body",
        5,
        "<i4",
        (
            Compared(
                "suction.sensed",
                None,
                "discrete",
                "",
                "object the pad's sensor sees (exact or off)",
            ),
        ),
    ),
    FrameField(
        "held_body",
        np.int32,
        "frame",
        "SuctionBlock",
        "held_body",
        6,
        "<i4",
        (Compared("suction.held", None, "discrete", "", "object the pad holds (exact or off)"),),
    ),
    FrameField(
        "hold_force_n",
        np.float64,
        "xyz",
        "SuctionBlock",
        "hold_force_n",
        7,
        "<f8",
        (Compared("hold.force", None, "norm", "N", "norm of the hold force difference"),),
    ),
    FrameField(
        "hold_torque_nm",
        np.float64,
        "xyz",
        "SuctionBlock",
        "hold_torque_nm",
        8,
        "<f8",
        (Compared("hold.torque", None, "norm", "N·m", "norm of the hold torque difference"),),
    ),
    FrameField(
        "pad_pose",
        np.float64,
        "pose",
        "PoseBlock",
        "pad_pose",
        4,
        "<f8",
        (
            Compared("pad.position", _POSITION, "norm", "m", "distance between pad tips"),
            Compared(
                "pad.orientation", _ORIENTATION, "angle", "rad", "angle between pad orientations"
            ),
        ),
    ),
    FrameField(
        "object_poses",
        np.float64,
        "object_pose",
        "PoseBlock",
        "object_poses",
        5,
        "<f8",
        (
            Compared(
                "objects.position",
                _POSITION,
                "norm",
                "m",
                "distance between object positions, every step",
            ),
            Compared(
                "objects.orientation",
                _ORIENTATION,
                "angle",
                "rad",
                "angle between object orientations, every step",
            ),
        ),
    ),
)
BY_NAME = {f.name: f for f in FRAME_FIELDS}
BLOCKS = ("JointBlock", "SuctionBlock", "PoseBlock")  # the MCAP block messages, in channel order
NAMES_FIELD = 3  # each block's names: joint names (JointBlock) or object names
NAMES_FIELD_NAME = {
    "JointBlock": "joint_names",
    "SuctionBlock": "object_names",
    "PoseBlock": "object_names",
}


def block_fields(block: str) -> tuple[FrameField, ...]:
    """The Frame fields a block message carries, step and t_ns first."""
    return tuple(f for f in FRAME_FIELDS if f.block in ("*", block))


COMPARED: tuple[tuple[FrameField, Compared], ...] = tuple(
    (f, c) for f in FRAME_FIELDS for c in f.compared
)
