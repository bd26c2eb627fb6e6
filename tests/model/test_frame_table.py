"""The Frame table is written once, in model/fields.py; five places spell it out again by hand
(the Frame NamedTuple, FrameColumns, FrameRows.pack_into, the table column stems, and the twin's
Frame built from World.state, in _read_frame and written out in its stepping loop) because each is
read by people and type checkers, or runs every physics step where a loop over the table costs
time. This file is the one check that holds them in line: adding a field to FRAME_FIELDS and
forgetting a copy fails here, not at import."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.fields import FRAME_FIELDS
from twin.model.types import Frame
from twin.record.mcap.blocks import BlockEncoder
from twin.record.rows import FrameRows
from twin.record.tables import _STEMS
from twin.sim.twin import Twin

NAMES = tuple(f.name for f in FRAME_FIELDS)


def test_frame_and_columns_name_the_table_in_order():
    assert Frame._fields == NAMES
    assert tuple(f.name for f in fields(FrameColumns)) == NAMES


def test_every_field_has_a_column_stem():
    assert tuple(_STEMS) == NAMES


def _distinct_frame(n_joints: int, n_objects: int) -> Frame:
    """A Frame whose every value differs from every other, so a field packed in the wrong place or
    order cannot come back equal."""
    counter = iter(range(1, 10_000))
    values = []
    for f in FRAME_FIELDS:
        shape = f.trailing(n_joints, n_objects)
        if f.dtype is np.bool_:
            values.append(True)
        elif not shape:
            values.append(next(counter))
        elif len(shape) == 1:
            values.append(tuple(next(counter) + 0.5 for _ in range(shape[0])))
        else:
            values.append(
                tuple(tuple(next(counter) + 0.25 for _ in range(shape[1])) for _ in range(shape[0]))
            )
    return Frame(*values)


@pytest.mark.parametrize("n_joints, n_objects", [(4, 1), (4, 2), (3, 5), (4, 0)])
def test_pack_into_writes_the_fields_in_the_table_order(n_joints, n_objects):
    rows = FrameRows(n_joints, n_objects)
    assert rows.size % 8 == 0 and rows.dtype.itemsize == rows.size
    frame = _distinct_frame(n_joints, n_objects)
    assert rows.frame(rows.pack(frame)) == frame


def test_each_column_is_its_wire_encoding():
    BlockEncoder({"JointBlock": b"", "SuctionBlock": b"", "PoseBlock": b""})
    for f in FRAME_FIELDS:
        column, wire = np.dtype(f.dtype), np.dtype(f.wire)
        assert column.itemsize == wire.itemsize and column.newbyteorder("<") == column, f.name


def test_the_twins_frame_has_the_tables_shapes_and_types():
    twin = Twin(TwinConfig())
    try:
        frame = twin.step(3)
        # the stepping loop writes the Frame out as _read_frame makes it: the two agree
        assert twin._read_frame() == frame
    finally:
        twin.close()
    n_joints, n_objects = len(frame.joint_q), len(frame.object_poses)
    assert n_objects >= 1
    for f, value in zip(FRAME_FIELDS, frame, strict=True):
        array = np.asarray(value)
        assert array.shape == f.trailing(n_joints, n_objects), f.name
        kind = np.dtype(f.dtype).kind
        assert array.dtype.kind == kind, f.name
