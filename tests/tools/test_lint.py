"""The project's lint: `ruff check twin tools tests` is clean, lines at most 100 characters included
(pyproject.toml's [tool.ruff]). A failure prints ruff's own report: file, line and rule."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ruff_check_is_clean():
    done = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "twin", "tools", "tests"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    report = done.stdout + done.stderr
    assert done.returncode == 0, f"ruff check failed (ruff is in the dev extra):\n{report}"
