"""SIGTERM and SIGHUP (CI cancelling a job, `timeout`, `docker stop`, a closed terminal) end a
command the way Ctrl-C does: the stack unwinds, recordings are finalized as `interrupted`, the
summary is printed, and the exit code is 128 + the signal's number."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class Terminated(BaseException):
    """A stop signal arrived. A BaseException, like KeyboardInterrupt, so no `except Exception` in a
    task swallows it; unlike KeyboardInterrupt, no command mistakes it for a quit key."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def __str__(self) -> str:
        return self.name


def _raise(signum: int, _frame) -> None:
    for other in STOP_SIGNALS:  # a second signal must not cut the finalizing short
        signal.signal(other, signal.SIG_IGN)
    raise Terminated(signum)


@contextmanager
def stop_signals_raise() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise Terminated in the main thread; restored after."""
    previous = {s: signal.signal(s, _raise) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
