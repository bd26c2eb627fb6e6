"""One error hierarchy; messages name the offending value and what was expected."""

from __future__ import annotations


def exception_text(err: BaseException) -> str:
    """str(err), or a stand-in when the exception cannot print itself (a user's class whose __str__
    raises, or a message holding a value too large to print). Never raises."""
    try:
        return str(err)
    except Exception as inner:  # noqa: BLE001 - any failure of __str__
        return f"<unprintable: its __str__ raised {type(inner).__name__}>"


class TwinError(Exception):
    """Base of every error the twin reports to a user (the CLI prints it as one line)."""

    exit_code = 2


class ConfigError(TwinError):
    """A profile, scene, key map or parameter is malformed or unknown."""


class OutputError(TwinError):
    """An output (a report, a folder, a recording being finalized) could not be written: the system
    refused it (permissions, a full disk). Exit 2, as for a bad output path."""


class HelperError(TwinError):
    """A helper process of the twin (the camera renderer) stopped or failed; the message says which
    and how (its exit code, or the error it sent). Exit 2, as the input errors it most often
    follows."""


class OutOfReach(TwinError):
    """A target lies outside the reachable annulus or the joint limits: the task failed (exit 1;
    3 is kept for runs that cannot be compared)."""

    exit_code = 1


class UnknownName(TwinError):
    """A joint, object or signal name that the profile does not know."""


class RecordingError(TwinError):
    """A recording file is missing, unreadable, truncated or not MCAP."""


class TaskError(TwinError):
    """A task raised; the run was closed cleanly and the exception recorded as an Event."""

    exit_code = 1


class TaskTimeout(TaskError):
    """A task ran past its bound of simulated time (`twin run --timeout`)."""
