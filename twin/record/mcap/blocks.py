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
        # each block's fields, step and t_ns first (every block carries those two)
        self._blocks = [[f.name for f in F.block_fields(block)] for block in F.BLOCKS]
        self._columns = [(f.name, np.dtype(f.dtype), f.wire) for f in F.FRAME_FIELDS]
        self._tags = {f.name: tag(f.number, LEN) for f in F.FRAME_FIELDS}
        self._heads: dict[tuple[int, ...], dict[str, bytes]] = {}  # byte counts -> field heads

    def messages(self, frames: FrameColumns, n: int | None = None) -> list[bytes]:
        """The block messages of the first `n` frames (all of them when None; at least one), from
        columns contiguous or not."""
        n = len(frames) if n is None else n
        data = {}
        for name, dtype, wire in self._columns:  # each field's bytes once, for every block
            column = getattr(frames, name)[:n]
            # a column of another type (not one of the twin's) as the wire's values
            data[name] = (column if column.dtype == dtype else column.astype(wire)).tobytes()
        heads = self._field_heads(data)
        out = []
        for fields, names in zip(self._blocks, self._names, strict=True):
            step, t_ns, *rest = fields
            parts = [heads[step], data[step], heads[t_ns], data[t_ns], names]
            for name in rest:
                parts += (heads[name], data[name])
            out.append(b"".join(parts))
        return out

    def _field_heads(self, data: dict[str, bytes]) -> dict[str, bytes]:
        """Each field's tag and length, for fields of these byte counts."""
        key = tuple(len(d) for d in data.values())
        heads = self._heads.get(key)
        if heads is None:
            heads = {name: self._tags[name] + varint(len(d)) for name, d in data.items()}
            self._heads[key] = heads
        return heads
