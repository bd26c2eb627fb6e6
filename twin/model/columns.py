"""Frames as columns: numpy arrays per field, the form recordings are loaded, compared and drawn in.

FrameColumns.from_frames(frames) and .frame(i) are exact inverses (float64 throughout).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from twin.model.fields import FRAME_FIELDS
from twin.model.types import Frame

# field name -> (dtype, trailing shape given (n_joints, n_objects)), from the one field description
FIELD_SPECS = {f.name: (f.dtype, f.trailing) for f in FRAME_FIELDS}
FIELD_NAMES = tuple(FIELD_SPECS)


@dataclass
class FrameColumns:
    """One array per Frame field; first axis is the frame index."""

    step: np.ndarray
    t_ns: np.ndarray
    joint_q: np.ndarray
    joint_qd: np.ndarray
    joint_effort: np.ndarray
    joint_target: np.ndarray
    suction_on: np.ndarray
    sensed_body: np.ndarray
    held_body: np.ndarray
    hold_force_n: np.ndarray
    hold_torque_nm: np.ndarray
    pad_pose: np.ndarray
    object_poses: np.ndarray

    def __len__(self) -> int:
        return int(self.step.shape[0])

    @staticmethod
    def empty(n: int, n_joints: int = 4, n_objects: int = 1) -> FrameColumns:
        return FrameColumns(
            **{
                name: np.zeros((n, *shape(n_joints, n_objects)), dtype=dtype)
                for name, (dtype, shape) in FIELD_SPECS.items()
            }
        )

    @staticmethod
    def from_frames(frames: list[Frame]) -> FrameColumns:
        n_obj = len(frames[0].object_poses) if frames else 0
        cols = {}
        for name, (dtype, shape) in FIELD_SPECS.items():
            values = [getattr(f, name) for f in frames]
            cols[name] = np.array(values, dtype=dtype).reshape((len(frames), *shape(4, n_obj)))
        return FrameColumns(**cols)

    def frame(self, i: int) -> Frame:
        return Frame(*(_PLAIN[f.shape](getattr(self, f.name)[i]) for f in FRAME_FIELDS))

    def slice(self, start: int, stop: int) -> FrameColumns:
        # by position, from the names' tuple: a recorder slices the ring at every wake-up (7.5 ->
        # 5.1 us a call, timeit; dataclasses.fields builds its tuple anew each call)
        return FrameColumns(*[getattr(self, name)[start:stop] for name in FIELD_NAMES])

    def copy(self) -> FrameColumns:
        """Contiguous copies of every column (of views into memory that will be written over)."""
        return FrameColumns(**{f.name: np.array(getattr(self, f.name)) for f in fields(self)})

    @staticmethod
    def concat(parts: list[FrameColumns]) -> FrameColumns:
        return FrameColumns(
            **{
                f.name: np.concatenate([getattr(p, f.name) for p in parts])
                for f in fields(FrameColumns)
            }
        )

    def equals(self, other: FrameColumns) -> bool:
        """Bit-identical (NaN-safe) equality of every column."""
        return all(
            getattr(self, f.name).shape == getattr(other, f.name).shape
            and getattr(self, f.name).tobytes() == getattr(other, f.name).tobytes()
            for f in fields(self)
        )


def _tuple(a: np.ndarray) -> tuple:
    return tuple(a.tolist())


# a column's row back to the Frame's plain Python value, by the field's shape
_PLAIN = {
    "frame": lambda v: v.item(),
    "joint": _tuple,
    "xyz": _tuple,
    "pose": _tuple,
    "object_pose": lambda a: tuple(_tuple(p) for p in a),
}
