"""The `twin` command in tests: in this process (main) or as a real subprocess."""

from __future__ import annotations

import socket

from twin.cli import main


def twin(capsys, *argv) -> tuple[int, str, str]:
    """`twin ARGV` in this process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def free_port() -> int:
    """A loopback TCP port free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
