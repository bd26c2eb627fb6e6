"""`twin serve` as a subprocess for tests: ServerProcess starts `twin serve --port 0` on loopback,
reads the port the server bound from its first line, and always terminates it (used by every remote
test)."""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Self

from coppeliasim_zmqremoteapi_client import RemoteAPIClient

STARTUP_TIMEOUT_S = 30.0


class ServerProcess:
    """A `twin serve` subprocess on a free loopback port; its output lines are kept in `lines`."""

    def __init__(self, *args: str) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if "--record" not in args:
            args = (*args, "--no-record")  # never write into the working tree
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "twin.cli",
                "serve",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                *args,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self.port = 0
        try:
            line = self.wait_for(r"listening on tcp://127\.0\.0\.1:(\d+)", STARTUP_TIMEOUT_S)
        except BaseException:
            self.stop()
            raise
        self.port = int(re.search(r":(\d+)", line).group(1))

    def _read(self) -> None:
        for line in self.proc.stdout:
            self._queue.put(line.rstrip("\n"))
        self._queue.put(None)

    def wait_for(self, pattern: str, timeout_s: float = 10.0) -> str:
        """The first output line (from now on, or already seen) matching `pattern`."""
        for line in self.lines:
            if re.search(pattern, line):
                return line
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self._queue.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                break
            if line is None:
                break
            self.lines.append(line)
            if re.search(pattern, line):
                return line
        raise AssertionError(
            f"no line matching {pattern!r}; output so far:\n" + "\n".join(self.lines)
        )

    def client(self) -> RemoteAPIClient:
        return RemoteAPIClient("127.0.0.1", self.port)

    def stop(self) -> int:
        """SIGINT (finalizes a running run's recording), then kill if it does not end."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        return self.proc.returncode

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
