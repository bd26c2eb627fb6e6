"""The one thing every receiver of a run is: a Sink gets each Frame, Command and Event as the run
produces them, then close(outcome, error) once when it ends. The methods here do nothing: a sink
overrides what it uses (a recorder all of them, an event log only on_event)."""

from __future__ import annotations

from twin.model.images import CameraImage
from twin.model.types import Command, Event, Frame

OUTCOMES = ("ok", "error", "interrupted")  # how a run ended, as close() is told


class Sink:
    """A receiver of a run. close(): outcome is one of OUTCOMES; error says what went wrong."""

    def on_frame(self, frame: Frame) -> None:
        pass

    def on_rows(self, rows, buf) -> None:
        """Many Frames at once, packed as `rows` (a record.rows.FrameRows) lays them out (the
        recorder process is fed so): the same as on_frame for each; writers override it to take the
        rows as columns."""
        for i in range(rows.count(buf)):
            self.on_frame(rows.frame(buf, i))

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
