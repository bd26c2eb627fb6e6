"""Record-and-replay PyBullet digital twin of the MTB SCARA pick-and-place robot."""

from __future__ import annotations

from os import PathLike
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from twin.model.joint_log import JointLog
    from twin.record.tables import RecordingWithTables


def load(path: str | PathLike) -> RecordingWithTables | JointLog:
    """Load an MCAP recording: its frames as numpy columns, commands, events, configuration and
    pictures, with its tables; or a ROS 2 bag's joint states.

    Args:
        path: an `.mcap` file written by `twin run --record`, `twin serve`, `twin teleop` or a
            replay; a file cut short loads what its finished chunks hold (not finalized). Or a
            ROS 2 bag: a folder holding `metadata.yaml`, or an MCAP file of profile `ros2`.

    Returns:
        The recording (`twin.model.recording.Recording`) with `to_arrow()` and `to_pandas()`; for
        a ROS 2 bag, its `/joint_states` (and `/tf`) as a `twin.model.joint_log.JointLog`.

    Raises:
        twin.model.errors.RecordingError: the file is missing, not MCAP, not a twin recording, or
            a bag without `/joint_states` (exit code 2 from the command line).
    """
    from twin.record.mcap.scan import is_bag

    if is_bag(path):
        from twin.ros2.bags import read_bag

        return read_bag(path)
    from twin.record.mcap.reader import load as load_mcap

    return load_mcap(path)
