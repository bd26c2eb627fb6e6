"""Benchmark section: the remote API's request path, measured with the official client.

Round-trip sim.getJointPosition calls per second, and stepped sim.step() steps per second, against a
`twin serve --stepped` subprocess on a free loopback port (targets on a 2-core machine: 5,000
calls/s and 2,000 steps/s). tools/bench.py calls bench(ctx); `python tools/bench_remote.py` runs it
alone.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace

from coppeliasim_zmqremoteapi_client import RemoteAPIClient

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support.server import ServerProcess  # the tests' `twin serve` subprocess, shared

CALLS = 10_000
STEPS = 3_000
TARGET_CALLS_PER_S = 5_000
TARGET_STEPS_PER_S = 2_000


def measure(port: int, calls: int = CALLS, steps: int = STEPS) -> tuple[float, float]:
    """(getJointPosition calls/s, sim.step() steps/s) over one official client."""
    sim = RemoteAPIClient("127.0.0.1", port).require("sim")
    h = sim.getObject("/MTB_axis1")
    for _ in range(500):  # warm up both ends
        sim.getJointPosition(h)
    t0 = time.perf_counter()
    for _ in range(calls):
        sim.getJointPosition(h)
    calls_per_s = calls / (time.perf_counter() - t0)
    sim.setStepping(True)
    sim.startSimulation()
    sim.setJointTargetPosition(h, 1.0)  # a moving arm, not an idle scene
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    steps_per_s = steps / (time.perf_counter() - t0)
    sim.setStepping(False)
    sim.stopSimulation()
    return calls_per_s, steps_per_s


def server_side_us(requests: int = 20_000) -> float:
    """Microseconds the server spends on one getJointPosition request (decode, call, encode), no
    transport."""
    import cbor2

    from twin.model.config import TwinConfig
    from twin.remote.server import Server
    from twin.remote.session import Scene

    scene = Scene(TwinConfig(), mode="stepped", log=lambda line: None)
    server = Server(scene, port=0, mode="stepped", log=lambda line: None)
    try:
        raw = cbor2.dumps(
            {"func": "sim.getJointPosition", "args": [11], "argsL": 1, "uuid": "bench"}
        )
        server.handle(raw, 0.0)
        t0 = time.perf_counter()
        for _ in range(requests):
            server.handle(raw, 0.0)
        return (time.perf_counter() - t0) / requests * 1e6
    finally:
        server.close()


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(1, int(getattr(ctx, "repeats", 1)))
    with ServerProcess("--stepped") as server:
        samples = [measure(server.port) for _ in range(repeats)]
    calls = statistics.median(s[0] for s in samples)
    steps = statistics.median(s[1] for s in samples)
    return [
        (
            "sim.getJointPosition round trips/s (official client, loopback)",
            f"{calls:,.0f} (target {TARGET_CALLS_PER_S:,})",
        ),
        ("stepped sim.step() steps/s", f"{steps:,.0f} (target {TARGET_STEPS_PER_S:,})"),
        ("round-trip latency", f"{1e6 / calls:.0f} µs per call, {1e6 / steps:.0f} µs per step"),
        ("server's share of a call (decode, dispatch, encode)", f"{server_side_us():.1f} µs"),
    ]


if __name__ == "__main__":
    for name, value in bench(SimpleNamespace(repeats=3)):
        print(f"{name}: {value}")
