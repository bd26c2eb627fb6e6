"""A unit's items run in child processes that may die without taking the job along.

A `Child` is a forked process that runs the batches of items sent to it, one result back per item,
in order, so the parent always knows which item is running. It dies with its parent
(PR_SET_PDEATHSIG, also on `kill -9`) and leaves Ctrl-C to it. `GuardedPool` keeps `jobs` children
busy with batches taken from an iterator (only as many as it has children: the window is bounded
whatever the job's size), and turns a child that dies (a segfault, os._exit, the OOM killer) or runs
past the wall-clock limit into a failed item: the item is run once more, alone in a fresh child
(`unit.confirm`); if it dies or hangs again, `unit.failed` says why, the rest of its batch goes on
in another child and so does the job. The local executor runs a pool of `jobs` children; a Dask
task runs its batch in a pool of one (`run_batch_guarded`), so the same holds on a cluster.
"""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from multiprocessing.connection import Connection, wait
from typing import Any

from twin.helpers import TWINS_SIGNALS
from twin.jobs.unit import Unit
from twin.model.errors import TwinError

# wall seconds an item may take: a number, None (no limit), or a callable that says it now
Limit = float | Callable[[], float | None] | None

PR_SET_PDEATHSIG = 1  # prctl(2)
# cgroup v2: oom_kill counts the processes the OOM killer ended
OOM_EVENTS = "/sys/fs/cgroup/memory.events"
# this process's ends of its children's pipes: a new child closes them, or a child would never
# read the end of its pipe while a sibling held that end open
_PARENT_ENDS: set[int] = set()


class Child:
    """One forked worker and the items it was sent and has not answered yet (`pending`, in the
    order it runs them)."""

    def __init__(self, unit: Unit) -> None:
        parent_end, child_end = socket.socketpair()
        parent_pid = os.getpid()
        sys.stdout.flush()
        sys.stderr.flush()
        # a Ctrl-C that lands during fork would be raised inside an at-fork hook, where Python
        # drops it: held back until the fork is done, it stops the parent as any other
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, TWINS_SIGNALS)
        pid = -1
        try:
            pid = os.fork()
        finally:
            if pid != 0:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        # the child: serve until the parent closes its end, never return into the parent's code
        if pid == 0:
            code = 0
            try:
                parent_end.close()
                for fd in _PARENT_ENDS:
                    os.close(fd)
                _serve(Connection(child_end.detach()), unit, parent_pid, mask)
            except BaseException:  # noqa: BLE001 - a child must end here, whatever happened
                code = 70
            finally:
                os._exit(code)
        child_end.close()
        self.pid = pid
        self.conn = Connection(parent_end.detach())
        _PARENT_ENDS.add(self.conn.fileno())
        self.pending: deque[int] = deque()
        self.started_s = time.monotonic()  # when the item pending[0] started
        # running one item again, alone: why its first run ended
        self.confirm: str | None = None
        self.timed_out = False
        self.limit_s = 0.0  # the limit it ran past, once timed_out
        self.oom_before = oom_kills()

    def send(self, items: list[int], *, confirm: str | None = None) -> None:
        self.pending.extend(items)
        self.confirm = confirm
        self.started_s = time.monotonic()
        self.conn.send((items, confirm is not None))

    def kill(self) -> str:
        """End the process now (if it still runs) and say how it ended."""
        try:
            os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        return self.reap()

    def reap(self) -> str:
        """Wait for the process to end; how it ended, as a failed item's reason."""
        _PARENT_ENDS.discard(self.conn.fileno())
        self.conn.close()
        try:
            _, status = os.waitpid(self.pid, 0)
        except ChildProcessError:
            return "worker died"
        code = os.waitstatus_to_exitcode(status)
        if code >= 0:
            return f"worker died: exit code {code}"
        sig = -code
        if sig == signal.SIGKILL and oom_kills() > self.oom_before:
            return "killed: out of memory"
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = "unknown signal"
        return f"worker died: signal {sig} ({name})"


def _serve(conn: Connection, unit: Unit, parent_pid: int, mask: set) -> None:
    """The child's loop: batches in, one message per item out, ("done", result) or ("stop",
    error). mask: the signal mask to restore once the child's own handlers are set."""
    libc = ctypes.CDLL(None, use_errno=True)
    prctl = getattr(libc, "prctl", None)
    if prctl is not None:
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL)  # dies with the parent, even by kill -9
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        return
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle (it stops us)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    while True:
        try:
            items, confirm = conn.recv()
        except EOFError:
            return
        for i in items:
            try:
                result = unit.confirm(i) if confirm else unit.run(i)
            except TwinError as err:  # a file that cannot be written: the job stops (one line)
                conn.send(("stop", err))
                return
            except Exception as err:  # noqa: BLE001 - a bug in the task's code fails its item only
                result = unit.failed(i, f"{type(err).__name__}: {err}", 0.0)
            conn.send(("done", result))
        sys.stdout.flush()


def oom_kills() -> int:
    """How many processes the OOM killer has ended in this cgroup (0 where that is not known)."""
    try:
        with open(OOM_EVENTS) as f:
            for line in f:
                name, _, value = line.partition(" ")
                if name == "oom_kill":
                    return int(value)
    except (OSError, ValueError):
        pass
    return 0


def limit_now(limit: Limit) -> float | None:
    """The wall seconds an item may take now: the limit itself, or what the callable says."""
    return limit() if callable(limit) else limit


class GuardedPool:
    """`jobs` children running the batches of one unit; `run` yields (item, result) as each item
    finishes. timeout_s: wall seconds an item may take (None: no limit), or a callable asked each
    time (a limit that follows the results so far)."""

    def __init__(self, unit: Unit, jobs: int, timeout_s: Limit = None) -> None:
        self.unit, self.jobs, self.limit = unit, jobs, timeout_s
        self.busy: list[Child] = []
        self.idle: list[Child] = []
        self.again: deque[list[int]] = deque()  # the rest of a batch whose child died
        # items to run once more, alone: (i, first reason)
        self.to_confirm: deque[tuple[int, str]] = deque()

    @property
    def timeout_s(self) -> float | None:
        return limit_now(self.limit)

    def run(self, batches: Iterable[list[int]]) -> Iterator[tuple[int, Any]]:
        source = iter(batches)
        self.unit.warm()  # once here, not in every child
        try:
            while True:
                while len(self.busy) < self.jobs and self._send(source):
                    pass
                if not self.busy:
                    return
                for child in self._ready():
                    done = self._answer(child)
                    if child.conn.closed or not child.pending:
                        self.busy.remove(child)
                        if not child.conn.closed:
                            self.idle.append(child)
                    if done is not None:
                        yield done
        finally:
            self.close()

    def _send(self, source: Iterator[list[int]]) -> bool:
        """Give the next work to an idle (or new) child: an item to confirm, the rest of a batch,
        or the next batch. False when there is none now."""
        if self.to_confirm:
            item, reason = self.to_confirm.popleft()
            work, confirm = [item], reason
        elif self.again:
            work, confirm = self.again.popleft(), None
        else:
            work, confirm = next(source, None), None
            if work is None:
                return False
        child = self.idle.pop() if self.idle else Child(self.unit)
        child.send(work, confirm=confirm)
        self.busy.append(child)
        return True

    def _ready(self) -> list[Child]:
        """The busy children with a message (or dead), after waiting until one has; a child past the
        time limit is marked and returned too."""
        timeout, limit_s = None, self.timeout_s
        if limit_s is not None:
            timeout = max(0.0, min(c.started_s for c in self.busy) + limit_s - time.monotonic())
        ready = wait([c.conn for c in self.busy], timeout)
        out = [c for c in self.busy if c.conn in ready]
        if limit_s is not None:
            now = time.monotonic()
            for c in self.busy:
                if c not in out and now - c.started_s >= limit_s:
                    c.limit_s = limit_s
                    c.timed_out = True
                    out.append(c)
        return out

    def _answer(self, child: Child) -> tuple[int, Any] | None:
        """Take one message from a child, or its death or time-out; (item, result) if one
        finished."""
        item = child.pending[0]
        if child.timed_out:
            child.kill()
            reason = f"timed out: no result after {child.limit_s:g} s of wall time"
        else:
            try:
                kind, value = child.conn.recv()
            except (EOFError, OSError):
                kind, value = "died", child.reap()
            if kind == "stop":
                raise value
            if kind == "done":
                child.pending.popleft()
                child.started_s = time.monotonic()
                return item, value
            reason = value
        wall_s = time.monotonic() - child.started_s
        child.pending.popleft()
        if child.pending:
            self.again.append(list(child.pending))
            child.pending.clear()
        # first time: run it once more, alone, before calling it a failure
        if child.confirm is None:
            self.to_confirm.append((item, reason))
            return None
        why = reason if reason == child.confirm else f"{reason} (first run: {child.confirm})"
        return item, self.unit.failed(item, why, wall_s)

    def close(self) -> None:
        """End the children: an idle one when it reads the end of its pipe, a busy one (Ctrl-C, an
        error) at once, its unanswered items dropped."""
        busy, idle, self.busy, self.idle = self.busy, self.idle, [], []
        for child in busy:
            if not child.conn.closed:
                child.kill()
        for child in idle:
            if not child.conn.closed:
                child.reap()


def run_batch_guarded(
    unit: Unit, items: list[int], timeout_s: Limit = None
) -> list[tuple[int, Any]]:
    """A batch's (item, result) pairs, run in a child of this process (what a Dask task runs): an
    item that kills its process or hangs is a failed one, the Dask worker lives on."""
    return list(GuardedPool(unit, 1, timeout_s).run([items]))
