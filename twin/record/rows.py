"""Frames as packed rows: one fixed-size little-endian record per Frame, laid out from model.fields.

The stepping loop packs each Frame into a preallocated buffer (a struct pack: about a microsecond,
no per-field work); whoever receives the buffer reads it back as numpy columns without touching a
row in Python (`columns`), or as Frames where it needs them (`frame`). The recorder process is fed
this way, and the MCAP writer keeps its block's frames so.
"""

from __future__ import annotations

import itertools
import struct

import numpy as np

from twin.model.columns import FrameColumns
from twin.model.fields import FRAME_FIELDS
from twin.model.types import Frame

_STRUCT_CODE = {np.int64: "q", np.int32: "i", np.float64: "d", np.bool_: "?"}


class FrameRows:
    """The packed-row layout of one scene's Frames (its joint and object counts fix the size)."""

    def __init__(self, n_joints: int, n_objects: int) -> None:
        self.n_joints, self.n_objects = n_joints, n_objects
        codes, dtype_fields, pack_args, unpack_parts, at = [], [], [], [], 0
        for f in FRAME_FIELDS:
            shape = f.trailing(n_joints, n_objects)
            count = int(np.prod(shape, dtype=np.int64))
            codes.append(f"{count}{_STRUCT_CODE[f.dtype]}")
            dtype_fields.append((f.name, np.dtype(f.dtype).newbyteorder("<"), shape))
            if f.shape == "frame":
                pack_args.append(f"f.{f.name}")
                unpack_parts.append(f"v[{at}]")
            elif f.shape == "object_pose":
                pack_args.append(f"*chain(f.{f.name})")
                width = shape[-1]  # a pose's numbers
                poses = [f"v[{at + width * k}:{at + width * (k + 1)}], " for k in range(n_objects)]
                unpack_parts.append(f"({''.join(poses)})")
            else:
                pack_args.append(f"*f.{f.name}")
                unpack_parts.append(f"v[{at}:{at + count}]")
            at += count
        self._struct = struct.Struct("<" + "".join(codes))
        self.size = self._struct.size  # bytes per row
        self.dtype = np.dtype(dtype_fields)  # packed: numpy's offsets are the struct's
        if self.dtype.itemsize != self.size:
            raise ImportError("twin.record.rows: the numpy row and the struct row disagree")
        # The pack and unpack expressions are written out from the field description once: as fast
        # as hand-written ones, which a loop over the fields is not (about 2.5 against 1.1 us a
        # frame).
        scope = {"pack_into": self._struct.pack_into, "unpack": self._struct.unpack_from,
                 "chain": itertools.chain.from_iterable, "Frame": Frame}
        self.pack_into = eval(
            f"lambda buf, offset, f: pack_into(buf, offset, {', '.join(pack_args)})", scope
        )
        self._unpack = eval(
            f"lambda buf, offset: (lambda v: "
            f"Frame({', '.join(unpack_parts)}))(unpack(buf, offset))",
            scope,
        )

    def pack(self, frame: Frame) -> bytes:
        """One Frame as its row."""
        buf = bytearray(self.size)
        self.pack_into(buf, 0, frame)
        return bytes(buf)

    def frame(self, buf, index: int = 0) -> Frame:
        """Row `index` of a buffer of rows as a Frame (the same values, bit for bit)."""
        return self._unpack(buf, index * self.size)

    def count(self, buf) -> int:
        """How many rows a buffer holds."""
        return len(buf) // self.size

    def records(self, buf) -> np.ndarray:
        """A buffer of rows as a numpy structured array (a view, no copy)."""
        return np.frombuffer(buf, dtype=self.dtype)

    def columns(self, buf, *, copy: bool = True) -> FrameColumns:
        """A buffer of rows as FrameColumns: each column a contiguous copy, or (copy=False) a
        strided view into the buffer, for a reader that copies the values out at once."""
        records = self.records(buf)
        if not copy:
            return FrameColumns(**{f.name: records[f.name] for f in FRAME_FIELDS})
        return FrameColumns(
            **{
                f.name: np.ascontiguousarray(records[f.name]).astype(f.dtype, copy=False)
                for f in FRAME_FIELDS
            }
        )
