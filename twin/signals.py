"""SIGTERM and SIGHUP (CI cancelling a job, `timeout`, `docker stop`, a closed terminal) end a
command the way Ctrl-C does: the stack unwinds, recordings are finalized as `interrupted`, the
summary is printed, and the exit code is 128 + the signal's number.

A command started with SIGINT ignored (a background job of a script: the shell sets it so, and
Python then leaves Ctrl-C ignored) would never end on Ctrl-C; the commands that run long unattended
(`twin sweep`, `twin search`, `twin check`, `twin view`, `twin export`) ask for it back
(`interrupt=True`), as `twin serve` sets its own."""

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
def stop_signals_raise(*, interrupt: bool = False) -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise Terminated in the main thread; restored after.
    interrupt: SIGINT raises KeyboardInterrupt too, even when this process started with it
    ignored."""
    previous = {s: signal.signal(s, _raise) for s in STOP_SIGNALS}
    if interrupt:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
