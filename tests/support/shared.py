"""A session fixture's folder made once for the whole run, not once per pytest-xdist worker."""

from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest


def made_once(
    tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], object]
) -> Path:
    """The folder `name` after make(folder) ran in it, once per run. Under xdist the workers share
    the run's base temporary folder (each has its own popen-gwN inside it): the first to ask makes
    the folder while the others wait on its lock, then all read it. A worker that dies drops its
    lock, and a make that fails leaves no mark, so the next one to ask tries again. Read what the
    folder holds; copy it before changing it."""
    if "PYTEST_XDIST_WORKER" not in os.environ:  # one process: its own folder, as before
        folder = tmp_path_factory.mktemp(name)
        make(folder)
        return folder
    root = tmp_path_factory.getbasetemp().parent  # this run's, shared by its workers
    folder, done = root / name, root / f"{name}.done"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, or its process dies
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)  # what a failed make left
            folder.mkdir()
            make(folder)
            done.touch()
    return folder
