"""The `rerun` binary as a child of `twin view`: on loopback ports, never outliving its parent.

A viewer child runs in its own process group (so stopping it stops anything it started), gets
SIGKILL from the kernel when the twin process dies, even by SIGKILL (Linux: PR_SET_PDEATHSIG), and
writes its log to a file: its banner and INFO lines are not ours to print, only its last line when
it fails. Ctrl-C, SIGTERM and SIGHUP unwind the stack (twin.signals, set up by the CLI), so the
`finally` that calls `stop` ends the child before the process exits.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO

from twin.model.errors import TwinError

LOOPBACK = "127.0.0.1"
STOP_WAIT_S = 10.0
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_LOG_PREFIX = re.compile(r"^\S+Z\s+[A-Z]+\s+\S+:\s+")  # "2026-...Z  WARN target: "
_RUST_SOURCE = re.compile(r" at \S+\.rs:\d+")


class ViewerError(TwinError):
    """The Rerun viewer could not be started or did not answer."""


def _die_with_parent(parent_pid: int):
    """A preexec_fn: the kernel sends SIGKILL to the child when its parent dies (Linux only)."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up before the fork, not in the child

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent_pid:  # the parent died before prctl: nobody would kill us later
            os.kill(os.getpid(), signal.SIGKILL)

    return preexec


def spawn(cmd: Sequence[str], log: IO[bytes], *, env: dict[str, str] | None = None,
          tmp_dir: str | os.PathLike | None = None) -> subprocess.Popen:
    """Start `cmd` in its own process group, dying with this process, its output going to `log`
    (a file, never a pipe: a chatty viewer must not block on a full pipe). With tmp_dir, the child's
    TMPDIR: the viewer makes a `rerun-data-*` folder there that a stopped viewer leaves behind."""
    env = dict(os.environ if env is None else env)
    if tmp_dir is not None:
        env["TMPDIR"] = str(tmp_dir)
    return subprocess.Popen(list(cmd), stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=env,
                            start_new_session=True,
                            # the only hook that runs in the child before exec; it calls only prctl
                            # and getppid
                            preexec_fn=_die_with_parent(os.getpid()))  # noqa: PLW1509


def stop(proc: subprocess.Popen) -> None:
    """End a child started by `spawn`, and anything it started (its own process group)."""
    for sig, wait_s in ((signal.SIGTERM, STOP_WAIT_S), (signal.SIGKILL, None)):
        with contextlib.suppress(ProcessLookupError):  # already gone
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=wait_s)
            return
        except subprocess.TimeoutExpired:
            continue


def last_log_line(log: str | os.PathLike | IO[bytes]) -> str:
    """The child's last log line without colours, timestamp, level, target or Rust source paths."""
    if isinstance(log, (str, os.PathLike)):
        text = Path(log).read_bytes().decode(errors="replace")
    else:
        log.seek(0)
        text = log.read().decode(errors="replace")
    lines = [_ANSI.sub("", ln).strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines:
        return ""
    return _RUST_SOURCE.sub("", _LOG_PREFIX.sub("", lines[-1]))


def loopback_ports(*wanted: tuple[str, int]) -> list[int]:
    """For each (option name, port): the port checked free on 127.0.0.1, or a free one for 0; all
    different. The numbers are handed to rerun, which binds them a moment later."""
    explicit = [port for _, port in wanted if port]
    if len(set(explicit)) != len(explicit):
        names = " and ".join(name for name, _ in wanted)
        raise ViewerError(f"{names} are the same port {explicit[0]}; expected different ports")
    chosen = []
    with contextlib.ExitStack() as held:  # keep each bound until all are picked, so they differ
        for name, port in sorted(wanted, key=lambda w: w[1] == 0):  # explicit ones first
            s = held.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            if port:  # a socket left in TIME_WAIT does not make a port busy (rerun reuses it too)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((LOOPBACK, port))
                if port:
                    s.listen()  # on Linux only listening proves nobody else listens there
            except OSError as err:
                raise ViewerError(
                    f"{name} {port}: {LOOPBACK}:{port} is already in use ({err.strerror}); "
                    f"expected a free port, or 0 for any free one"
                ) from err
            chosen.append((name, s.getsockname()[1]))
    by_name = dict(chosen)
    return [by_name[name] for name, _ in wanted]


def wait_listening(
    proc: subprocess.Popen, ports: Sequence[int], log: IO[bytes], what: str, timeout_s: float
) -> None:
    """Wait until the child accepts TCP connections on every port; ViewerError if it exits first
    (with its last log line) or is not up within timeout_s."""
    deadline = time.monotonic() + timeout_s
    pending = list(ports)
    while pending:
        if proc.poll() is not None:
            raise ViewerError(
                f"{what} exited with code {proc.returncode}: {last_log_line(log) or 'no output'}"
            )
        try:
            with socket.create_connection((LOOPBACK, pending[0]), timeout=1.0):
                pending.pop(0)
                continue
        except OSError:
            pass
        if time.monotonic() > deadline:
            raise ViewerError(
                f"{what} did not listen on {LOOPBACK}:{pending[0]} within {timeout_s:.0f} s"
            )
        time.sleep(0.1)
