"""The Rerun writer's component columns, built from numpy arrays straight as Arrow.

`send_columns` takes columns as anything with a component descriptor and an Arrow array. The SDK's
archetype `.columns()` makes them through its general converters: about 0.1-0.5 ms a call whatever
the batch's length (validation, a partition of ones, casts), which over a batch's 16 calls was most
of the Rerun writer's fixed cost a batch. Here each column is one numpy cast and a pyarrow wrap,
with the descriptors, Arrow types and packed pad colours taken once from the SDK's own archetypes:
the arrays are the SDK's, value for value (tests/record/rerun/test_columns.py holds them to it).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr


class Column:
    """One component's column as send_columns reads it: a descriptor and one row a frame."""

    __slots__ = ("array", "descriptor")

    def __init__(self, descriptor, array: pa.Array) -> None:
        self.descriptor, self.array = descriptor, array

    def component_descriptor(self):
        return self.descriptor

    def as_arrow_array(self) -> pa.Array:
        return self.array


def _kinds(columns) -> dict[str, tuple[object, pa.DataType]]:
    """An archetype's sample columns: (descriptor, Arrow type) by component name ("translation"),
    in the SDK's order."""
    kinds = {}
    for c in columns:
        descriptor = c.component_descriptor()
        kinds[descriptor.component.rpartition(":")[2]] = (descriptor, c.as_arrow_array().type)
    return kinds


class ColumnMaker:
    """Makes the Transform3D, Cylinders3D and Scalars columns the writer sends, up to `capacity`
    frames a batch, each frame one row of one instance."""

    def __init__(self, capacity: int, colors_rgb: list[tuple[int, int, int]]) -> None:
        self._offsets = pa.array(np.arange(capacity + 1, dtype=np.int32))
        one = np.zeros((1, 3))
        self._transform_kinds = _kinds(
            rr.Transform3D.columns(
                translation=one,
                quaternion=np.array([[0.0, 0.0, 0.0, 1.0]]),
                parent_frame=["a"],
                child_frame=["b"],
            )
        )
        self._cylinder_kinds = _kinds(rr.Cylinders3D.columns(centers=one, colors=[(0, 0, 0)]))
        self._scalar_kind = _kinds(rr.Scalars.columns(scalars=[0.0]))["scalars"]
        # the SDK's own packing of each colour (one u32 a colour)
        self._colors = np.array(
            [rr.components.ColorBatch([rgb]).as_arrow_array()[0].as_py() for rgb in colors_rgb],
            dtype=np.uint32,
        )

    def _list(self, kind: pa.DataType, values: pa.Array, n: int) -> pa.Array:
        """`values` (one a frame) as rows of one."""
        return pa.ListArray.from_arrays(self._offsets.slice(0, n + 1), values, type=kind)

    def _vectors(self, kind: pa.DataType, values: np.ndarray) -> pa.Array:
        """(n, k) numbers as a column of one k-vector a row, in the type the SDK gives it."""
        flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).reshape(-1))
        vectors = pa.FixedSizeListArray.from_arrays(flat, type=kind.value_type)
        return self._list(kind, vectors, len(values))

    def transforms(
        self, translations: np.ndarray, quaternions: np.ndarray, frames=None
    ) -> list[Column]:
        """Transform3D columns: translations (n, 3), quaternions (n, 4) as x, y, z, w, and, when
        given, (parent, child) frame names as Arrow string arrays of at least n."""
        n = len(translations)
        values = {"translation": translations, "quaternion": quaternions}
        if frames is not None:
            values["parent_frame"], values["child_frame"] = frames
        columns = []
        for name, (descriptor, kind) in self._transform_kinds.items():
            if name not in values:
                continue
            if name.endswith("_frame"):
                array = self._list(kind, values[name].slice(0, n), n)
            else:
                array = self._vectors(kind, values[name])
            columns.append(Column(descriptor, array))
        return columns

    def cylinders(self, centers: np.ndarray, color_index: np.ndarray) -> list[Column]:
        """Cylinders3D columns: centres (n, 3) and each frame's colour, as an index into the
        colours given at construction."""
        n = len(centers)
        c_desc, c_kind = self._cylinder_kinds["centers"]
        k_desc, k_kind = self._cylinder_kinds["colors"]
        colors = pa.array(self._colors[color_index])
        return [
            Column(c_desc, self._vectors(c_kind, centers)),
            Column(k_desc, self._list(k_kind, colors, n)),
        ]

    def scalars(self, values: np.ndarray) -> list[Column]:
        """A Scalars column of one float64 a frame."""
        desc, kind = self._scalar_kind
        array = pa.array(np.ascontiguousarray(values, dtype=np.float64))
        return [Column(desc, self._list(kind, array, len(values)))]
