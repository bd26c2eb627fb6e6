"""Helper processes of a run (the recorders, the camera renderer): forked from the twin's process,
joined to it by a pipe, and deaf to the signals that are the twin's to handle."""

from __future__ import annotations

import gc
import multiprocessing
import os
import signal
import weakref
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

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
    # The helper's garbage collector leaves the objects it inherits alone (a full collection would
    # walk them all, copying every page it touches): they stay frozen in the helper; this side's
    # collector takes them back at once.
    gc.freeze()
    try:
        process.start()
    finally:
        gc.unfreeze()
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


def split_cpus() -> tuple[set[int], set[int]] | None:
    """({the CPU the calling thread runs on now}, every other CPU this process may use), or None
    (it may use one CPU only, or the system does not say). Helpers forked onto the others while the
    thread keeps to its own never share its core: Linux wakes a process on the core of the thread
    that woke it (the twin's), where the two would take turns while the other core idled."""
    try:
        allowed = os.sched_getaffinity(0)
        with open("/proc/thread-self/stat", encoding="ascii") as stat:
            # field 39, "processor", counting from 1; the name (field 2) may hold spaces
            here = int(stat.read().rsplit(")", 1)[1].split()[36])
    except (AttributeError, OSError, ValueError, IndexError):
        return None
    others = allowed - {here}
    return ({here}, others) if others and here in allowed else None


@contextmanager
def forking_on(cpus: set[int] | None) -> Iterator[None]:
    """While it lasts, the calling thread may run on `cpus` only (None: unchanged), so that the
    processes it forks inherit them; afterwards it may run where it could before."""
    before = keep_to(cpus)
    try:
        yield
    finally:
        keep_to(before)


def keep_to(cpus: set[int] | None) -> set[int] | None:
    """Let the calling thread run on `cpus` only (None: leave it); returns the CPUs it could use
    before (None when unchanged), for a later keep_to() to give them back."""
    if cpus is None:
        return None
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, cpus)
    return before
