"""The twin's errors by their public name: what a task file, a script or a test catches
(`from twin.errors import TaskError`). They are defined at the bottom of the house, in
twin.model.errors, where every package can raise them; this name stays because a task's source is
its identity in every recording, and the built-in tasks and users' task files import it."""

from twin.model.errors import (
    ConfigError,
    HelperError,
    OutOfReach,
    OutputError,
    RecordingError,
    TaskError,
    TaskTimeout,
    TwinError,
    UnknownName,
    exception_text,
)

__all__ = [
    "ConfigError",
    "HelperError",
    "OutOfReach",
    "OutputError",
    "RecordingError",
    "TaskError",
    "TaskTimeout",
    "TwinError",
    "UnknownName",
    "exception_text",
]
