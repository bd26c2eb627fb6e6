"""Helper processes of a run (the recorders, the camera renderer): forked from the twin's process,
joined to it by a pipe, and deaf to the signals that are the twin's to handle."""

from __future__ import annotations

import multiprocessing
import signal
import weakref
from collections.abc import Callable, Sequence

# the twin handles them, then closes its helpers
TWINS_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def start_helper(
    owner: object, target: Callable, args: tuple, *, name: str, other_ends: Sequence = ()
):
    """Fork `target(conn, *args)` as a daemon process joined to this one by a pipe; returns this
    side's end of the pipe and the process.

    - Ctrl-C, SIGTERM and SIGHUP are the twin's: the helper ignores them. They stay blocked from the
      fork until it does, so one sent to the process group right at the fork cannot kill it before
      it can finish its work.
    - The helper closes its copies of this side's end and of `other_ends` (the ends of helpers
      started before it): with one of them open, the twin's death would go unseen.
    - This side's end is closed at exit, or when `owner` goes, if nobody closed it: the helper then
      sees EOF and ends. Otherwise multiprocessing's exit handler (terminate, then join daemon
      children) would wait forever for a child that ignores SIGTERM."""
    ctx = multiprocessing.get_context("fork")
    conn, child_conn = ctx.Pipe()
    process = ctx.Process(
        target=_helper_main,
        args=(target, child_conn, [conn, *other_ends], args),
        name=name,
        daemon=True,
    )
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, TWINS_SIGNALS)
    try:
        process.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    child_conn.close()
    weakref.finalize(owner, conn.close)
    return conn, process


def _helper_main(target: Callable, conn, twins_ends: list, args: tuple) -> None:
    for end in twins_ends:  # the fork's copies of the twin's ends
        end.close()
    for signum in TWINS_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, TWINS_SIGNALS)
    target(conn, *args)
