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
    FrameField(
        name="step",
        dtype=np.int64,
        shape="frame",
        block="*",
        proto_name="step",
        number=1,
        wire="<i8",
    ),
    FrameField(
        name="t_ns",
        dtype=np.int64,
        shape="frame",
        block="*",
        proto_name="t_ns",
        number=2,
        wire="<i8",
    ),
    FrameField(
        name="joint_q",
        dtype=np.float64,
        shape="joint",
        block="JointBlock",
        proto_name="position",
        number=4,
        wire="<f8",
        compared=(
            Compared(
                "joints.position", None, "joint", "rad|m", "joint angle (wrapped) or Z travel"
            ),
        ),
    ),
    FrameField(
        name="joint_qd",
        dtype=np.float64,
        shape="joint",
        block="JointBlock",
        proto_name="velocity",
        number=5,
        wire="<f8",
        compared=(Compared("joints.velocity", None, "abs", "rad/s|m/s", "joint velocity"),),
    ),
    FrameField(
        name="joint_effort",
        dtype=np.float64,
        shape="joint",
        block="JointBlock",
        proto_name="effort",
        number=6,
        wire="<f8",
        compared=(Compared("joints.effort", None, "abs", "N·m|N", "motor torque or force"),),
    ),
    FrameField(
        name="joint_target",
        dtype=np.float64,
        shape="joint",
        block="JointBlock",
        proto_name="target",
        number=7,
        wire="<f8",
        compared=(Compared("joints.target", None, "joint", "rad|m", "motor target (wrapped)"),),
    ),
    FrameField(
        name="suction_on",
        dtype=np.bool_,
        shape="frame",
        block="SuctionBlock",
        proto_name="on",
        number=4,
        wire="|u1",
        compared=(Compared("suction.on", None, "discrete", "", "pad switched on (exact or off)"),),
    ),
    FrameField(
        name="sensed_body",
        dtype=np.int32,
        shape="frame",
        block="SuctionBlock",
        proto_name="sensed_body",
        number=5,
        wire="<i4",
        compared=(
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
        name="held_body",
        dtype=np.int32,
        shape="frame",
        block="SuctionBlock",
        proto_name="held_body",
        number=6,
        wire="<i4",
        compared=(
            Compared("suction.held", None, "discrete", "", "object the pad holds (exact or off)"),
        ),
    ),
    FrameField(
        name="hold_force_n",
        dtype=np.float64,
        shape="xyz",
        block="SuctionBlock",
        proto_name="hold_force_n",
        number=7,
        wire="<f8",
        compared=(Compared("hold.force", None, "norm", "N", "norm of the hold force difference"),),
    ),
    FrameField(
        name="hold_torque_nm",
        dtype=np.float64,
        shape="xyz",
        block="SuctionBlock",
        proto_name="hold_torque_nm",
        number=8,
        wire="<f8",
        compared=(
            Compared("hold.torque", None, "norm", "N·m", "norm of the hold torque difference"),
        ),
    ),
    FrameField(
        name="pad_pose",
        dtype=np.float64,
        shape="pose",
        block="PoseBlock",
        proto_name="pad_pose",
        number=4,
        wire="<f8",
        compared=(
            Compared("pad.position", _POSITION, "norm", "m", "distance between pad tips"),
            Compared(
                "pad.orientation", _ORIENTATION, "angle", "rad", "angle between pad orientations"
            ),
        ),
    ),
    FrameField(
        name="object_poses",
        dtype=np.float64,
        shape="object_pose",
        block="PoseBlock",
        proto_name="object_poses",
        number=5,
        wire="<f8",
        compared=(
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
