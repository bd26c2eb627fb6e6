"""Frames as packed rows: one fixed-size little-endian record per Frame, laid out from model.fields.

Rows are how Frames travel inside record/, and nowhere else: the stepping loop packs each Frame
into a preallocated buffer (one struct pack, about a microsecond, no per-field work), and whoever
receives the buffer hands it on as FrameColumns, numpy views of its rows, without touching a row in
Python. The recorder process's ring is fed so (record.ring), and so is a writer that takes Frames
one at a time (FrameBatch): writers only ever see columns.
"""

from __future__ import annotations

import struct
from itertools import chain

import numpy as np

from twin.model.columns import FrameColumns
from twin.model.fields import FRAME_FIELDS
from twin.model.types import Frame

_STRUCT_CODE = {np.int64: "q", np.int32: "i", np.float64: "d", np.bool_: "?"}


class FrameRows:
    """The packed-row layout of one scene's Frames (its joint and object counts fix the size)."""

    def __init__(self, n_joints: int, n_objects: int) -> None:
        self.n_joints, self.n_objects = n_joints, n_objects
        self._one_object = n_objects == 1  # the usual scene: its pose unpacked without a chain
        # Each field starts at a multiple of its item size (a row at one of 8): the writers copy
        # columns out of the rows, which numpy does about twice as fast from aligned memory.
        codes, names, formats, offsets, at = [], [], [], [], 0
        for f in FRAME_FIELDS:
            shape = f.trailing(n_joints, n_objects)
            item = np.dtype(f.dtype).newbyteorder("<")
            pad = -at % item.itemsize
            codes.append(f"{pad}x{int(np.prod(shape, dtype=np.int64))}{_STRUCT_CODE[f.dtype]}")
            at += pad
            names.append(f.name)
            formats.append((item, shape))
            offsets.append(at)
            at += item.itemsize * int(np.prod(shape, dtype=np.int64))
        codes.append(f"{-at % 8}x")
        self._struct = struct.Struct("<" + "".join(codes))
        self._pack_into = self._struct.pack_into
        self.size = self._struct.size  # bytes per row
        self.dtype = np.dtype(
            {"names": names, "formats": formats, "offsets": offsets, "itemsize": self.size}
        )

    def pack_into(self, buf, offset: int, frame: Frame) -> None:
        """Write `frame` as the row at byte `offset` of `buf`, its fields in model.fields' order
        (spelled out for speed; tests/model/test_frame_table.py holds it to the table). The Frame
        is unpacked once, not read field by field: 1.3 us a row instead of 2.2 (timeit). One
        object's pose is unpacked as it is: chaining one tuple cost 0.3-0.4 us more (timeit)."""
        step, t_ns, q, qd, effort, target, on, sensed, held, force, torque, pad, poses = frame
        self._pack_into(
            buf,
            offset,
            step,
            t_ns,
            *q,
            *qd,
            *effort,
            *target,
            on,
            sensed,
            held,
            *force,
            *torque,
            *pad,
            *(poses[0] if self._one_object else chain.from_iterable(poses)),
        )

    def pack(self, frame: Frame) -> bytes:
        """One Frame as its row."""
        buf = bytearray(self.size)
        self.pack_into(buf, 0, frame)
        return bytes(buf)

    def count(self, buf) -> int:
        """How many rows a buffer holds."""
        return len(buf) // self.size

    def records(self, buf) -> np.ndarray:
        """A buffer of rows as a numpy structured array (a view, no copy; the pad bytes between
        fields are zeros)."""
        return np.frombuffer(buf, dtype=self.dtype)

    def columns(self, buf, *, copy: bool = True) -> FrameColumns:
        """A buffer of rows as FrameColumns: each column a contiguous copy, or (copy=False) a
        strided view into the buffer, for a reader that copies what it keeps before the buffer is
        written again."""
        records = self.records(buf)
        if not copy:
            return FrameColumns(**{f.name: records[f.name] for f in FRAME_FIELDS})
        return FrameColumns(
            **{
                f.name: np.ascontiguousarray(records[f.name]).astype(f.dtype, copy=False)
                for f in FRAME_FIELDS
            }
        )

    def frame(self, buf, index: int = 0) -> Frame:
        """Row `index` of a buffer of rows as a Frame (the same values, bit for bit)."""
        return self.columns(buf[index * self.size : (index + 1) * self.size]).frame(0)


class FrameBatch:
    """Frames taken one at a time and handed on as columns, `capacity` at a time or sooner (take):
    what a writer's on_frame does with the twin's Frames, so that on_frames is its one way in. The
    columns are views of a buffer that the next add_frame() writes over: the writer copies what it
    keeps."""

    def __init__(self, n_joints: int, n_objects: int, capacity: int) -> None:
        self.rows = FrameRows(n_joints, n_objects)
        self._buf = bytearray(capacity * self.rows.size)
        self._end = len(self._buf)
        self._at = 0  # bytes written

    def add_frame(self, frame: Frame) -> FrameColumns | None:
        """Keep `frame`; the batch's columns once it is full, else None."""
        self.rows.pack_into(self._buf, self._at, frame)
        self._at += self.rows.size
        return self.take() if self._at == self._end else None

    def take(self) -> FrameColumns | None:
        """The frames kept so far as columns (None when there are none); the batch starts again."""
        if not self._at:
            return None
        frames = self.rows.columns(memoryview(self._buf)[: self._at], copy=False)
        self._at = 0
        return frames
