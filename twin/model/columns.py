"""Frames as columns: numpy arrays per field, the form recordings are loaded, compared and drawn in.

FrameColumns.from_frames(frames) and .frame(i) are exact inverses (float64 throughout).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from twin.model.types import Frame

# field name -> (dtype, trailing shape given (n_joints, n_objects))
FIELD_SPECS = {
    "step": (np.int64, lambda j, b: ()),
    "t_ns": (np.int64, lambda j, b: ()),
    "joint_q": (np.float64, lambda j, b: (j,)),
    "joint_qd": (np.float64, lambda j, b: (j,)),
    "joint_effort": (np.float64, lambda j, b: (j,)),
    "joint_target": (np.float64, lambda j, b: (j,)),
    "suction_on": (np.bool_, lambda j, b: ()),
    "sensed_body": (np.int32, lambda j, b: ()),
    "held_body": (np.int32, lambda j, b: ()),
    "hold_force_n": (np.float64, lambda j, b: (3,)),
    "hold_torque_nm": (np.float64, lambda j, b: (3,)),
    "pad_pose": (np.float64, lambda j, b: (7,)),
    "object_poses": (np.float64, lambda j, b: (b, 7)),
}


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
        return FrameColumns(**{
            name: np.zeros((n, *shape(n_joints, n_objects)), dtype=dtype) for name, (dtype, shape) in FIELD_SPECS.items()
        })

    @staticmethod
    def from_frames(frames: list[Frame]) -> FrameColumns:
        n_obj = len(frames[0].object_poses) if frames else 0
        cols = {}
        for name, (dtype, shape) in FIELD_SPECS.items():
            values = [getattr(f, name) for f in frames]
            cols[name] = np.array(values, dtype=dtype).reshape((len(frames), *shape(4, n_obj)))
        return FrameColumns(**cols)

    def frame(self, i: int) -> Frame:
        def t(a: np.ndarray) -> tuple:
            return tuple(a.tolist())

        return Frame(
            step=int(self.step[i]), t_ns=int(self.t_ns[i]),
            joint_q=t(self.joint_q[i]), joint_qd=t(self.joint_qd[i]),
            joint_effort=t(self.joint_effort[i]), joint_target=t(self.joint_target[i]),
            suction_on=bool(self.suction_on[i]), sensed_body=int(self.sensed_body[i]), held_body=int(self.held_body[i]),
            hold_force_n=t(self.hold_force_n[i]), hold_torque_nm=t(self.hold_torque_nm[i]),
            pad_pose=t(self.pad_pose[i]), object_poses=tuple(t(p) for p in self.object_poses[i]),
        )

    def slice(self, start: int, stop: int) -> FrameColumns:
        return FrameColumns(**{f.name: getattr(self, f.name)[start:stop] for f in fields(self)})

    @staticmethod
    def concat(parts: list[FrameColumns]) -> FrameColumns:
        return FrameColumns(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(FrameColumns)})

    def equals(self, other: FrameColumns) -> bool:
        """Bit-identical (NaN-safe) equality of every column."""
        return all(
            getattr(self, f.name).shape == getattr(other, f.name).shape
            and getattr(self, f.name).tobytes() == getattr(other, f.name).tobytes()
            for f in fields(self)
        )


class FrameCollector:
    """A sink that keeps every Frame, Command and Event in memory (tests, comparisons)."""

    def __init__(self) -> None:
        self.frames: list[Frame] = []
        self.commands = []
        self.events = []

    def on_frame(self, frame: Frame) -> None:
        self.frames.append(frame)

    def on_command(self, command) -> None:
        self.commands.append(command)

    def on_event(self, event) -> None:
        self.events.append(event)

    def columns(self) -> FrameColumns:
        return FrameColumns.from_frames(self.frames)


class ColumnCollector:
    """A sink that keeps Frames as numpy columns, converted in chunks: about a fifth of the memory
    of Frame tuples, for long runs (replay, check). Commands and Events are kept as they come."""

    CHUNK_FRAMES = 4096

    def __init__(self) -> None:
        self._chunks: list[FrameColumns] = []
        self._pending: list[Frame] = []
        self.commands = []
        self.events = []

    def on_frame(self, frame: Frame) -> None:
        self._pending.append(frame)
        if len(self._pending) >= self.CHUNK_FRAMES:
            self._chunks.append(FrameColumns.from_frames(self._pending))
            self._pending = []

    def on_command(self, command) -> None:
        self.commands.append(command)

    def on_event(self, event) -> None:
        self.events.append(event)

    def columns(self) -> FrameColumns:
        parts = self._chunks + ([FrameColumns.from_frames(self._pending)] if self._pending else [])
        if not parts:
            return FrameColumns.from_frames([])
        return parts[0] if len(parts) == 1 else FrameColumns.concat(parts)
