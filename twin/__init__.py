"""Record-and-replay PyBullet digital twin of the MTB SCARA pick-and-place robot."""

from __future__ import annotations

from os import PathLike
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from twin.record.tables import RecordingWithTables


def load(path: str | PathLike) -> RecordingWithTables:
    """Load an MCAP recording: its frames as numpy columns, commands, events, configuration and
    pictures, with its tables.

    Args:
        path: an `.mcap` file written by `twin run --record`, `twin serve`, `twin teleop` or a
            replay; a file cut short loads what its finished chunks hold (not finalized).

    Returns:
        The recording (`twin.model.recording.Recording`) with `to_arrow()` and `to_pandas()`.

    Raises:
        twin.model.errors.RecordingError: the file is missing, not MCAP, or not a twin recording
            (exit code 2 from the command line).
    """
    from twin.record.mcap.reader import load as load_mcap

    return load_mcap(path)
