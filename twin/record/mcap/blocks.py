"""The per-step block messages (JointBlock, SuctionBlock, PoseBlock) of a run of frames.

A block message is its frames' step and t_ns, its names, then each of its Frame fields as one packed
field, frame after frame ([frame][item]; model.fields says which field goes where and in which wire
type). A column's bytes in memory are its wire type's bytes (little-endian, a bool one byte of 0 or
1), so a field costs one copy out of its column; the tags and lengths are worked out once for each
frame count.
"""

from __future__ import annotations

import numpy as np

from twin.model import fields as F
from twin.model.columns import FrameColumns
from twin.record.mcap.wire import LEN, tag, varint


class BlockEncoder:
    """Encodes frames, as columns, into the block messages, in model.fields' block order."""

    def __init__(self, names: dict[str, bytes]) -> None:
        """`names`: each block's encoded names field (joint names for JointBlock, object names
        else)."""
        self._names = [names[block] for block in F.BLOCKS]
        self._fields = [F.block_fields(block) for block in F.BLOCKS]  # step and t_ns first
        self._dtypes = [[np.dtype(f.dtype) for f in fields] for fields in self._fields]
        for f in F.FRAME_FIELDS:
            column, wire = np.dtype(f.dtype), np.dtype(f.wire)
            if column.itemsize != wire.itemsize or column.newbyteorder("<") != column:
                raise ImportError(f"twin.record.mcap.blocks: {f.name}'s column is not its wire")
        self._heads: dict[tuple[int, ...], list[bytes]] = {}  # (block, sizes) -> field heads

    def messages(self, frames: FrameColumns, n: int | None = None) -> list[bytes]:
        """The block messages of the first `n` frames (all of them when None; at least one), from
        columns contiguous or not."""
        n = len(frames) if n is None else n
        out = []
        for b, (fields, names) in enumerate(zip(self._fields, self._names, strict=True)):
            columns = []
            for f, dtype in zip(fields, self._dtypes[b], strict=True):
                column = getattr(frames, f.name)[:n]
                # a column of another type (not one of the twin's) as the wire's values
                columns.append(column if column.dtype == dtype else column.astype(f.wire))
            heads = self._field_heads(b, columns)
            parts = [heads[0], columns[0].tobytes(), heads[1], columns[1].tobytes(), names]
            for head, column in zip(heads[2:], columns[2:], strict=True):
                parts += (head, column.tobytes())
            out.append(b"".join(parts))
        return out

    def _field_heads(self, block: int, columns: list[np.ndarray]) -> list[bytes]:
        """Each field's tag and length in block message `block`, for columns of these sizes."""
        key = (block, *(c.size for c in columns))
        heads = self._heads.get(key)
        if heads is None:
            heads = [
                tag(f.number, LEN) + varint(c.size * np.dtype(f.wire).itemsize)
                for f, c in zip(self._fields[block], columns, strict=True)
            ]
            self._heads[key] = heads
        return heads
