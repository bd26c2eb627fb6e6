"""The one thing every receiver of a run is: a Sink gets the run's Frames, Commands, Events and
pictures in the order the run produces them, then close(outcome, error) once when it ends.

Frames come one at a time (on_frame, as the twin steps) or many at once as columns (on_frames, as
the recorder process and a loaded recording hand them on); a sink that takes columns gathers the
single Frames into columns itself. The methods here do nothing, but on_frames hands each frame to
on_frame: a sink overrides what it uses (a writer on_frames, an event log only on_event)."""

from __future__ import annotations

from twin.model.columns import FrameColumns
from twin.model.images import CameraImage
from twin.model.types import Command, Event, Frame

OUTCOMES = ("ok", "error", "interrupted")  # how a run ended, as close() is told


class Sink:
    """A receiver of a run. close(): outcome is one of OUTCOMES; error says what went wrong.

    `reads_pad_pose`: whether on_frame reads a Frame's pad_pose. A sink that sets it False (and one
    without an on_frame of its own, which sees no Frames) lets the twin leave it out while stepping:
    such a sink's Frames may hold None there. The twin works it out every step while any sink reads
    it, and `twin.frame` always has it."""

    reads_pad_pose = True

    def on_frame(self, frame: Frame) -> None:
        pass

    def on_frames(self, frames: FrameColumns) -> None:
        """Many Frames at once, as columns: the same as on_frame for each. The columns may be views
        of memory that is written over once this returns: a sink copies what it keeps."""
        for i in range(len(frames)):
            self.on_frame(frames.frame(i))

    def on_command(self, command: Command) -> None:
        pass

    def on_event(self, event: Event) -> None:
        pass

    def on_image(self, image: CameraImage) -> None:
        """A camera's picture of the frame at image.step (it arrives after that frame)."""

    def close(self, outcome: str = "ok", error: str = "") -> None:
        pass


def close_all(sinks, outcome: str, error: str) -> Exception | None:
    """Close every sink with the run's outcome, even when one fails; the first failure, or None."""
    first: Exception | None = None
    for sink in sinks:
        try:
            sink.close(outcome=outcome, error=error)
        except Exception as err:  # noqa: BLE001 - keep closing the others
            first = first or err
    return first


def reads_pad_pose(sink) -> bool:
    """Whether the twin must work out each Frame's pad pose for `sink` (any object with on_frame):
    it takes Frames (its on_frame is its own) and does not say it leaves the pad pose alone."""
    return type(sink).on_frame is not Sink.on_frame and getattr(sink, "reads_pad_pose", True)
