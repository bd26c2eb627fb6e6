"""The pandas example of docs/how-to/datasets.md runs as written and prints what the page says."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_readme_pandas_example(tmp_path):
    pytest.importorskip("matplotlib")
    page = (ROOT / "docs" / "how-to" / "datasets.md").read_text()
    code = re.search(
        r"```python\n(import matplotlib\.pyplot as plt\n.*?)```", page, re.DOTALL
    ).group(1)
    claimed = re.search(
        r"<!-- doctest: output -->\n```text.*\n(.*?)\n```", page[page.index(code) :]
    ).group(1)
    (tmp_path / "recordings").symlink_to(ROOT / "recordings")
    (tmp_path / "runs").mkdir()
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MPLBACKEND": "Agg", "HOME": str(tmp_path)},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == claimed
    png = (tmp_path / "runs" / "pick_place_joints.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
