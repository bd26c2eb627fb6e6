"""A pick_place cycle recorded by the real `twin run` with the overhead and wrist cameras (MCAP and
.rrd)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def camera_run_paths(folder: Path) -> dict[str, Path]:
    """Where record_camera_run(folder) writes: {"mcap": path, "rrd": path}."""
    return {"mcap": folder / "camera.mcap", "rrd": folder / "camera.rrd"}


def record_camera_run(folder: Path, *extra: str) -> dict[str, Path]:
    """`twin run pick_place --cycles 1 --camera overhead --camera wrist` into folder, in its own
    process: {"mcap": path, "rrd": path}."""
    mcap, rrd = camera_run_paths(folder).values()
    # the rerun SDK may write its analytics config under HOME
    env = {**os.environ, "HOME": str(folder)}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "pick_place",
            "--cycles",
            "1",
            "--camera",
            "overhead",
            "--camera",
            "wrist",
            *extra,
            "--record",
            str(mcap),
            "--rrd",
            str(rrd),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return camera_run_paths(folder)
