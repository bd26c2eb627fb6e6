"""`twin sweep --executor dask`: a real LocalCluster (2 single-threaded worker processes on
127.0.0.1), the same results as the local pool, also when a worker process is killed mid-sweep."""

from __future__ import annotations

import subprocess
import sys
import time

import psutil
import pyarrow.parquet as pq
import pytest

from twin.cli.main import main

pytestmark = pytest.mark.slow  # a cluster starts in seconds; each test runs one

SWEEP = [
    "pick_place",
    "--scenarios",
    "40",
    "--seed",
    "11",
    "--vary",
    "box.x_m=uniform(0.17,0.23)",
    "--vary",
    "box.y_m=uniform(0.67,0.73)",
    "--vary",
    "box.mass_kg=choice(0.1,0.5)",
    "--param",
    "cycles=1",
    "--param",
    "pause_s=0.1",
    "--param",
    "max_error_m=0.02",
    "--batch",
    "2",
]


def _table(folder):
    return pq.read_table(folder / "results.parquet").drop(["wall_s"])


def _workers(pid: int) -> list[psutil.Process]:
    """The Dask worker processes the sweep started (spawned by its nannies; not the children the
    workers fork to run their scenarios in)."""
    out = []
    for child in psutil.Process(pid).children(recursive=True):
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                out.append(child)
        except psutil.NoSuchProcess:
            pass
    pids = {w.pid for w in out}
    return [w for w in out if w.ppid() not in pids]


def test_a_killed_dask_worker_changes_nothing(tmp_path, capsys):
    assert main(["sweep", *SWEEP, "--quiet", "--jobs", "1", "--out", str(tmp_path / "local")]) == 0
    capsys.readouterr()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "sweep",
            *SWEEP,
            "--executor",
            "dask",
            "--jobs",
            "2",
            "--out",
            str(tmp_path / "dask"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # the first batches are back: both workers are busy with the rest
        first = proc.stderr.readline()
        assert first.startswith("sweep: "), first + proc.stderr.read()
        workers = _workers(proc.pid)
        assert len(workers) == 2
        for conn in psutil.Process(proc.pid).net_connections(kind="inet"):
            if conn.status == psutil.CONN_LISTEN:
                assert conn.laddr.ip == "127.0.0.1"  # the scheduler listens on loopback only
        for w in workers:
            for conn in w.net_connections(kind="inet"):
                if conn.status == psutil.CONN_LISTEN:
                    assert conn.laddr.ip == "127.0.0.1"
        victim = workers[0]
        # SIGKILL mid-batch: its tasks go to the other worker (and the nanny's new one)
        victim.kill()
        victim.wait(10)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert "40 scenarios" in stdout and "(dask)" in stdout
    assert _table(tmp_path / "dask").equals(_table(tmp_path / "local"))
    local_failures = sorted(p.name for p in (tmp_path / "local" / "failures").iterdir())
    assert sorted(p.name for p in (tmp_path / "dask" / "failures").iterdir()) == local_failures
    for name in local_failures:
        assert (tmp_path / "dask" / "failures" / name).read_bytes() == (
            tmp_path / "local" / "failures" / name
        ).read_bytes()
    time.sleep(0.5)
    assert not psutil.pid_exists(victim.pid) or victim.status() == psutil.STATUS_ZOMBIE


def test_twin_check_runs_mcap_and_sweep_goldens_on_dask(tmp_path, capsys):
    folder = tmp_path / "goldens"
    folder.mkdir()
    assert main(["run", "pick_place", "--cycles", "1", "--record", str(folder / "a.mcap")]) == 0
    assert main(["run", "seed002", "--robot", "seed002", "--record", str(folder / "b.mcap")]) == 0
    (folder / "s.toml").write_text(
        'task = "pick_place"\nscenarios = 8\nseed = 4\n[params]\ncycles = 1\n'
        'pause_s = 0.1\n[vary]\n"box.x_m" = "uniform(0.19, 0.21)"\n'
    )
    assert main(["check", str(folder / "s.toml"), "--update"]) == 0  # written by the local executor
    capsys.readouterr()
    assert main(["check", str(folder), "--executor", "dask", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    assert "3 match" in out and "s.toml" in out and "a.mcap" in out and "b.mcap" in out
