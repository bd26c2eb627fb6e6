"""Sinks that keep a run in memory: FrameCollector (Frames as they came: tests, comparisons) and
ColumnCollector (numpy columns, for long runs: replay, check)."""

from __future__ import annotations

from twin.model.columns import FrameColumns
from twin.model.sink import Sink
from twin.model.types import Frame


class _Collector(Sink):
    """Commands, Events and camera pictures, kept as they come (what both collectors share)."""

    def __init__(self) -> None:
        self.commands = []
        self.events = []
        self.images = []  # model.images.CameraImage, as they came

    def on_command(self, command) -> None:
        self.commands.append(command)

    def on_event(self, event) -> None:
        self.events.append(event)

    def on_image(self, image) -> None:
        self.images.append(image)


class FrameCollector(_Collector):
    """A sink that keeps every Frame, Command and Event in memory (tests, comparisons)."""

    def __init__(self) -> None:
        super().__init__()
        self.frames: list[Frame] = []

    def on_frame(self, frame: Frame) -> None:
        self.frames.append(frame)

    def columns(self) -> FrameColumns:
        return FrameColumns.from_frames(self.frames)


class ColumnCollector(_Collector):
    """A sink that keeps Frames as numpy columns, converted in chunks: about a fifth of the memory
    of Frame tuples, for long runs (replay, check). Commands and Events are kept as they come."""

    CHUNK_FRAMES = 4096

    def __init__(self) -> None:
        super().__init__()
        self._chunks: list[FrameColumns] = []
        self._pending: list[Frame] = []

    def on_frame(self, frame: Frame) -> None:
        self._pending.append(frame)
        if len(self._pending) >= self.CHUNK_FRAMES:
            self._chunks.append(FrameColumns.from_frames(self._pending))
            self._pending = []

    def columns(self) -> FrameColumns:
        parts = self._chunks + ([FrameColumns.from_frames(self._pending)] if self._pending else [])
        if not parts:
            return FrameColumns.from_frames([])
        return parts[0] if len(parts) == 1 else FrameColumns.concat(parts)
