"""`twin serve` as a process: startup, the port it reports, clean shutdown, bad command lines
(ServerProcess, in tests/support/server.py, starts it)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from support.server import ServerProcess

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out


def test_serve_reports_its_port_serves_and_shuts_down_cleanly_on_sigint(tmp_path):
    with ServerProcess(
        "--stepped", "--robot", "seed002", "--record", str(tmp_path / "run.mcap")
    ) as server:
        sim = server.client().require("sim")
        assert sim.getObjectAlias(sim.getObject("/AB")) == "AB"
        sim.startSimulation()
        sim.setStepping(True)
        for _ in range(5):
            sim.step()
        assert server.stop() == 0
        server.wait_for(r"shutting down")
        # the run was still going: shutting down ends it and finalizes its recording
        server.wait_for(r"simulation stopped: run 1 lasted 5 steps.*run\.mcap")
    assert (tmp_path / "run.mcap").stat().st_size > 0


def test_serve_refuses_a_busy_port_with_one_line():
    with ServerProcess("--stepped") as first:
        proc = subprocess.run(
            [sys.executable, "-m", "twin.cli", "serve", "--port", str(first.port)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert proc.returncode == 2
    assert f"cannot listen on tcp://127.0.0.1:{first.port}" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--port", "70000"], "port '70000' is invalid"),
        (["--speed", "0"], "speed 0.0 is out of range"),
        (["--step-grace", "0"], "step grace 0.0 s is out of range; expected 0.01..3600 seconds"),
        (["--step-grace", "nan"], "step grace nan s is out of range"),
        (["--robot", "nope"], "unknown robot 'nope'"),
    ],
)
def test_serve_rejects_bad_options(args, expected):
    proc = subprocess.run(
        [sys.executable, "-m", "twin.cli", "serve", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 2
    assert expected in proc.stderr


def test_realtime_follows_the_wall_clock_until_a_client_steps():
    with ServerProcess("--realtime", "--speed", "2") as server:
        sim = server.client().require("sim")
        dt_s = sim.getSimulationTimeStep()
        t_start_sent = time.monotonic()
        sim.startSimulation()
        t_start_done = time.monotonic()
        time.sleep(0.3)
        t_query_sent = time.monotonic()
        t_sim = sim.getSimulationTime()
        t_query_done = time.monotonic()
        # the server steps up to floor(elapsed wall time x speed / dt) before it answers
        assert (
            2 * (t_query_sent - t_start_done) - 2 * dt_s
            <= t_sim
            <= 2 * (t_query_done - t_start_sent) + dt_s
        )
        sim.setStepping(True)  # now this client's sim.step() is the clock
        frozen = sim.getSimulationTime()
        time.sleep(0.1)
        assert sim.getSimulationTime() == frozen
        sim.step()
        assert sim.getSimulationTime() == pytest.approx(frozen + dt_s, abs=1e-12)
        t_resume = time.monotonic()
        sim.setStepping(False)
        time.sleep(0.1)
        t_now = sim.getSimulationTime()
        # back on the wall clock from where the stepping left it: no jump over the stepped time
        assert frozen + dt_s < t_now <= frozen + dt_s + 2 * (time.monotonic() - t_resume) + dt_s
        sim.stopSimulation()


def test_a_speed_the_machine_cannot_keep_lets_time_slip_and_keeps_answering():
    with ServerProcess("--realtime", "--speed", "1000") as server:
        sim = server.client().require("sim")
        sim.startSimulation()
        times = []
        for _ in range(10):
            time.sleep(0.05)
            # each answered: no catch-up that grows without end
            times.append(sim.getSimulationTime())
        server.wait_for(r"cannot keep up with 1000x real time here; simulated time slips")
        assert times == sorted(times) and times[-1] > times[0]
        # 0.5 s of wall time at 1000x would be 500 simulated s; capped catch-ups give far less
        assert times[-1] - times[0] < 100.0
