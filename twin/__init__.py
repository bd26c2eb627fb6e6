"""Record-and-replay PyBullet digital twin of the MTB SCARA pick-and-place robot."""

from __future__ import annotations

from os import PathLike
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from twin.record.tables import RecordingWithTables


def load(path: str | PathLike) -> RecordingWithTables:
    """Load an MCAP recording as a twin.model.recording.Recording (frames as numpy columns,
    commands, events) with its tables (to_arrow, to_pandas)."""
    from twin.record.mcap.reader import load as load_mcap

    return load_mcap(path)
