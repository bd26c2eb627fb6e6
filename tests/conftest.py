"""Shared by every test folder (they mirror twin's packages): tests/ on sys.path for the `support`
helpers, and the pick_place recordings that many modules only read, made once per session."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))  # `import support...` from any folder, whatever pytest's import mode

from support.camera_run import camera_run_paths, record_camera_run
from support.runs import collect_pick_place
from support.shared import made_once

ROOT = TESTS.parent  # the checkout: README.md, recordings/, tools/
# twin check appends its table to the file GitHub names here: the suite's many checks would fill
# the CI job's summary (tests/report sets it where it tests that)
os.environ.pop("GITHUB_STEP_SUMMARY", None)
FIXTURES = TESTS / "fixtures"


def pytest_configure(config: pytest.Config) -> None:
    """Once, in the run's first process: twin/ compiled to bytecode. The suite starts hundreds of
    twin processes and workers (593 ended normally in one run, besides those killed or forked);
    where PYTHONDONTWRITEBYTECODE is set (as on our machines) none writes its bytecode, so each
    compiled the twin modules it imports anew: 0.13 s of CPU per `twin info` (0.60 -> 0.48 s,
    five runs each), more for run, check and diff."""
    if hasattr(config, "workerinput"):  # an xdist worker: its controller did it
        return
    import compileall

    compileall.compile_dir(ROOT / "twin", quiet=1)


def pytest_itemcollected(item: pytest.Item) -> None:
    """A test that uses a module-scoped fixture runs on the worker of its module's other such tests
    (pyproject's `--dist loadgroup`): under xdist's plain `load`, tests of one module went to both
    workers and each made the module's fixtures, e.g. test_remote_seeds' seed_runs twice (13 s
    of setup on each worker in one run). xdist schedules such groups first, largest first."""
    info = getattr(item, "_fixtureinfo", None)
    defs = info.name2fixturedefs.values() if info is not None else ()
    if any(d and d[-1].scope == "module" for d in defs):
        item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


@pytest.fixture(scope="session")
def pick_place_mcap(tmp_path_factory):
    """One pick_place cycle recorded to MCAP in this process (open_recorders), with a FrameCollector
    of what the twin sent beside it: (path, collector). Read it; copy it before changing it."""
    path = tmp_path_factory.mktemp("pick_place_mcap") / "pick.mcap"
    return path, collect_pick_place(path)


@pytest.fixture(scope="session")
def pick_place_cli(tmp_path_factory):
    """One pick_place cycle recorded as MCAP and .rrd by the real `twin run` command, in its own
    process, once for the run's workers: {"tmp": folder, "mcap": path, "rrd": path}. Read them;
    copy them before changing them."""
    tmp = made_once(tmp_path_factory, "pick_place_cli", _record_pick_place_cli)
    return {"tmp": tmp, "mcap": tmp / "pick_place.mcap", "rrd": tmp / "pick_place.rrd"}


def _record_pick_place_cli(tmp: Path) -> None:
    mcap, rrd = tmp / "pick_place.mcap", tmp / "pick_place.rrd"
    # the rerun SDK may write its analytics config under HOME
    env = {**os.environ, "HOME": str(tmp)}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "pick_place",
            "--cycles",
            "1",
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


@pytest.fixture(scope="session")
def camera_run(tmp_path_factory):
    """One pick_place cycle recorded by the real `twin run` with the overhead and wrist cameras
    (320x240, 15 Hz), MCAP and .rrd, once for the run's workers: {"mcap": path, "rrd": path}. Read
    them; copy them before changing them."""
    return camera_run_paths(made_once(tmp_path_factory, "camera_run", record_camera_run))
