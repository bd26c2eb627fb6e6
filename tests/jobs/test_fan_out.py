"""Every command that fans out (`twin search -j 2`, `twin check -j 2`, `twin sweep -j 2`) ends the
same way, for real, in real processes: a `kill -9` of the parent leaves no process of it alive 5 s
later, and SIGINT and SIGTERM end it promptly with what finished written, also when it was started
with SIGINT ignored (as a script's background job is)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = sorted(str(p) for p in (ROOT / "recordings").glob("pick_place_*.mcap"))
SEARCH = [
    "search",
    "pick_place",
    "--vary",
    "box.x_m=0.1..0.3",
    "--param",
    "cycles=10",  # 41 runs of one cycle ended the search in 2.4 s, before a signal reached it
    "--param",
    "pause_s=0.1",
    "--budget",
    "200",
    "-j",
    "2",
]
SWEEP = [
    "sweep",
    "pick_place",
    "--scenarios",
    "10000",
    "--vary",
    "box.x_m=uniform(0.19,0.21)",
    "--param",
    "cycles=1",
    "--save",
    "none",
    "--quiet",
    "-j",
    "2",
]


def _start(argv: list[str], *, sigint: object = signal.SIG_DFL) -> subprocess.Popen:
    """`python -m twin ARGV` in its own session, SIGINT set to `sigint` before it starts."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}

    def prepare() -> None:
        signal.signal(signal.SIGINT, sigint)

    return subprocess.Popen(
        [sys.executable, "-m", "twin", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
        preexec_fn=prepare,  # noqa: PLW1509 - the signal disposition a shell would hand it
        start_new_session=True,
    )


def _workers(proc: subprocess.Popen, count: int = 2) -> list[psutil.Process]:
    """The parent's descendants once `count` of its direct children run (the workers)."""
    parent = psutil.Process(proc.pid)
    deadline = time.monotonic() + 120
    while True:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the workers never started"
        if len(parent.children()) >= count:
            time.sleep(1.0)  # at work, past their start
            # still there: not a pool closing between two rounds (seen once on a loaded machine)
            found = parent.children(recursive=True)
            if len(found) >= count:
                return found
        time.sleep(0.05)


def _alive(processes: list[psutil.Process]) -> list[psutil.Process]:
    out = []
    for p in processes:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


def _kill_9_leaves_nothing(proc: subprocess.Popen) -> None:
    workers = _workers(proc)
    assert len(workers) >= 2
    proc.kill()  # SIGKILL: no handler runs, no finally
    proc.wait()
    time.sleep(5.0)
    left = _alive(workers)
    for p in left:  # leave nothing behind for the next test either
        p.kill()
    assert not left, [p.cmdline() for p in left]


def test_kill_9_of_search_leaves_no_process(tmp_path):
    _kill_9_leaves_nothing(_start([*SEARCH, "--out", str(tmp_path / "s"), "-q"]))


@pytest.fixture(scope="module")
def check_args(tmp_path_factory) -> list[str]:
    """`twin check` of the short shipped goldens, then four copies of a 40-cycle run: the short
    ones finish first, the long ones keep both workers busy for seconds (the shipped ones alone
    took 0.2-0.3 s each and the check could end before a signal reached it)."""
    folder = tmp_path_factory.mktemp("long_goldens")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin",
            "run",
            "pick_place",
            "--cycles",
            "40",
            "--record",
            str(folder / "long_0.mcap"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    for k in range(1, 4):
        shutil.copy(folder / "long_0.mcap", folder / f"long_{k}.mcap")
    assert len(GOLDENS) >= 4
    return ["check", *GOLDENS, *sorted(str(p) for p in folder.glob("long_*.mcap")), "-j", "2"]


def test_kill_9_of_check_leaves_no_process(check_args):
    _kill_9_leaves_nothing(_start(check_args))


def _stops(proc: subprocess.Popen, signum: int) -> str:
    """Send signum to the parent alone once its workers run; it must end within 30 s with
    128 + signum, leaving none of its workers; its stdout."""
    workers = _workers(proc)
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum, err
    time.sleep(0.5)
    assert not _alive(workers)
    return out


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_sweep_started_with_sigint_ignored_ends_on_a_stop_signal(tmp_path, signum):
    out = tmp_path / "sweep"
    _stops(_start([*SWEEP, "--out", str(out)], sigint=signal.SIG_IGN), signum)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["planned"] == 10_000


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_search_started_with_sigint_ignored_ends_on_a_stop_signal(tmp_path, signum):
    out = tmp_path / "search"
    printed = _stops(_start([*SEARCH, "--out", str(out), "-q"], sigint=signal.SIG_IGN), signum)
    data = json.loads((out / "search.json").read_text())
    assert data["stopped"] == "interrupted" and "(interrupted)" in printed


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_check_started_with_sigint_ignored_ends_on_a_stop_signal(check_args, signum):
    printed = _stops(_start(check_args, sigint=signal.SIG_IGN), signum)
    assert "interrupted: " in printed  # what finished, as a table, before the exit


CRASHING_TASK = '''import os


def run(twin):
    """Moves once; kills its own process when a file named crash sits beside it."""
    twin.wait(0.2)
    if os.path.exists(os.path.join(os.path.dirname(__file__), "crash")):
        os._exit(9)
    twin.wait(0.2)
'''


def test_check_j2_names_a_golden_whose_worker_died_and_checks_the_rest(tmp_path, capsys):
    """A golden whose re-run kills its process is run once more alone, then one "error" line naming
    how the worker died; the other goldens are checked as usual, and the exit code is 1."""
    from support.cli import twin

    (tmp_path / "task.py").write_text(CRASHING_TASK)
    for name in ("a", "b"):
        golden = tmp_path / f"{name}.mcap"
        code, _, err = twin(capsys, "run", tmp_path / "task.py", "--record", golden)
        assert code == 0, err
    (tmp_path / "crash").write_text("")
    (tmp_path / "other.py").write_text(CRASHING_TASK.replace('"crash"', '"never"'))
    code, _, err = twin(capsys, "run", tmp_path / "other.py", "--record", tmp_path / "c.mcap")
    assert code == 0, err
    goldens = [tmp_path / f"{n}.mcap" for n in ("a", "b", "c")]
    code, out, _ = twin(capsys, "check", *goldens, "-j", "2")
    assert code == 1, out
    lines = {Path(line.split()[0]).name: line for line in out.splitlines() if ".mcap " in line}
    assert "worker died: exit code 9" in lines["a.mcap"] and " error " in lines["a.mcap"]
    assert "worker died: exit code 9" in lines["b.mcap"]
    assert " match " in lines["c.mcap"]
