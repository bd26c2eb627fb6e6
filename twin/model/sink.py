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
    """A receiver of a run. close(): outcome is one of OUTCOMES; error says what went wrong."""

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
