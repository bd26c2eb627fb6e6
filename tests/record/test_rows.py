"""record.rows: Frames packed as rows come back bit for bit, as Frames and as columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.model.columns import FrameColumns
from twin.model.sink import Sink
from twin.model.types import Frame
from twin.record.rows import FrameBatch, FrameRows
from twin.verify.collectors import FrameCollector


def _frame(step: int, n_objects: int) -> Frame:
    value = math.pi * (step + 1)
    return Frame(step, step * 4_166_667, (value, -value, 1e-300, -0.0), (math.inf, 1.0, 2.0, 3.0),
                 (4.0, 5.0, 6.0, 7.0), (0.1, 0.2, 0.3, 0.4), step % 2 == 1, step % 3 - 1, -1,
                 (1.5, 2.5, 3.5), (-1.5, -2.5, float("nan")), (0.0, 0.1, 0.2, 0.0, 0.0, 0.6, 0.8),
                 tuple((0.5 * k, 0.7, 0.05, 0.0, 0.0, 0.0, 1.0) for k in range(n_objects)))


@pytest.mark.parametrize("n_objects", [0, 1, 3])
def test_rows_give_back_every_frame_and_the_columns_bit_for_bit(n_objects):
    rows = FrameRows(4, n_objects)
    frames = [_frame(i, n_objects) for i in range(5)]
    buf = bytearray(rows.size * len(frames))
    for i, frame in enumerate(frames):
        rows.pack_into(buf, i * rows.size, frame)
    assert rows.count(buf) == 5 and bytes(buf[:rows.size]) == rows.pack(frames[0])
    for i, frame in enumerate(frames):
        back = rows.frame(buf, i)
        assert repr(back) == repr(frame)  # repr: NaN compares unequal to itself
        assert type(back.suction_on) is bool and type(back.held_body) is int
    expected = FrameColumns.from_frames(frames) if n_objects else None
    for copy in (True, False):
        columns = rows.columns(bytes(buf), copy=copy)
        if expected is not None:
            assert FrameColumns(
                **{name: np.ascontiguousarray(getattr(columns, name)) for name in Frame._fields}
            ).equals(expected)
        assert columns.object_poses.shape == (5, n_objects, 7)


def test_a_sink_without_on_frames_gets_each_frame_in_order():
    rows = FrameRows(4, 1)
    frames = [_frame(i, 1) for i in range(3)]
    collector = FrameCollector()
    Sink.on_frames(collector, rows.columns(b"".join(rows.pack(f) for f in frames), copy=False))
    assert [f.step for f in collector.frames] == [0, 1, 2] and repr(collector.frames) == repr(
        frames
    )


@pytest.mark.parametrize("capacity", [1, 4, 64])
def test_a_batch_hands_on_every_frame_once_in_order(capacity):
    """FrameBatch: full batches from add_frame, the rest from take, views of one reused buffer."""
    batch = FrameBatch(4, 2, capacity)
    frames = [_frame(i, 2) for i in range(10)]
    handed = []
    for frame in frames:
        columns = batch.add_frame(frame)
        if columns is not None:
            assert len(columns) == capacity
            handed += [columns.frame(i) for i in range(len(columns))]
    rest = batch.take()
    assert (rest is None) == (10 % capacity == 0) and batch.take() is None
    handed += [rest.frame(i) for i in range(len(rest))] if rest is not None else []
    assert repr(handed) == repr(frames)
