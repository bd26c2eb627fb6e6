"""A folder that refuses new files, for tests of a failed write: `chmod 0o555` for a user, and
`chattr +i` (immutable) as root, whom permissions do not stop. Skips the test where neither makes
the folder refuse a file (root on a file system without the immutable flag)."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def read_only(folder: Path) -> Iterator[Path]:
    """`folder`, refusing new files and renames into it until the block ends."""
    root = os.geteuid() == 0
    if root:
        made = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, check=False)
        if made.returncode != 0:
            pytest.skip(f"root, and chattr +i failed: {made.stderr.decode().strip()}")
    else:
        folder.chmod(0o555)
    try:
        probe = folder / ".probe"
        try:
            probe.write_text("")
        except OSError:
            pass
        else:
            probe.unlink()
            pytest.skip(f"{folder} still takes new files")
        yield folder
    finally:
        if root:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        else:
            folder.chmod(0o755)
