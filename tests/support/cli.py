"""The `twin` command in tests: in this process (main) or as a real subprocess."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

from twin.cli import main

# the installed `twin` executable, or the same command through this interpreter
TWIN = [shutil.which("twin")] if shutil.which("twin") else [sys.executable, "-m", "twin.cli"]

# a task file that never ends (signals, --timeout, re-record kills): it moves and reports simulated
# time
ENDLESS_TASK = '''
def run(twin):
    i = 0
    while True:
        twin.move_to(*[(0.5, 0.2), (0.3, 0.6)][i % 2], settle=False)
        twin.wait(0.25)
        print(f"t_s={twin.t_s!r}", flush=True)
        i += 1
'''


def twin(capsys, *argv) -> tuple[int, str, str]:
    """`twin ARGV` in this process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def twin_child(
    *args, env: dict[str, str] | None = None, cwd: Path | None = None
) -> subprocess.CompletedProcess:
    """`python -m twin ARGS` in a child process, with env added to this one's (one BLAS thread);
    in cwd, which `-m` puts first on sys.path."""
    full = {**os.environ, "OPENBLAS_NUM_THREADS": "1", **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "twin", *map(str, args)],
        check=False,
        capture_output=True,
        text=True,
        env=full,
        cwd=cwd,
        timeout=600,
    )


def free_port() -> int:
    """A loopback TCP port free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
