"""Benchmark section: the twin itself, without recording.

pick_place (2 cycles, mtb) in steps per wall second and as a ratio to physics-only; the twin's own
cost per step over bare stepSimulation; idle stepping; building a twin. `python tools/bench_twin.py`
runs it alone (with the baseline).
"""

from __future__ import annotations

import statistics
import sys
import time

from twin.model.config import TwinConfig
from twin.model.profiles import PROFILES
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task

CYCLES = 2
IDLE_STEPS = 5_000


def pick_place_steps(profile: str = "mtb") -> int:
    """One run of pick_place with no sinks; returns the physics steps it took."""
    twin = Twin(TwinConfig(profile=PROFILES[profile]))
    try:
        run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
        return twin.step_index
    finally:
        twin.close()


def _timed_pick_place(clock=time.perf_counter) -> float:
    """steps/s of the task alone (building the twin is timed separately), timed by `clock`."""
    twin = Twin(TwinConfig())
    try:
        t0 = clock()
        run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
        return twin.step_index / (clock() - t0)
    finally:
        twin.close()


PAIRS = 3  # twin_cost_us_per_step's pairs a repeat


def twin_cost_us_per_step(repeats: int, pairs: int = PAIRS) -> float:
    """The twin's own cost per step over the reads floor (bench_record.reads_floor_steps_per_s: the
    same motion on the bare World with a Frame's engine reads): its commands, suction rule, Frame
    and settle checks. Each pair runs the reads floor and then the twin, each timed in the thread's
    CPU time (neither waits for anything: what a busy moment of another process takes from a short
    run is left out); the median over repeats x pairs of 1/twin - 1/reads. Runs a few seconds apart
    on a shared machine differ by more than the cost itself, so the two runs of a pair follow each
    other."""
    from bench_record import reads_floor_steps_per_s

    costs = []
    for _ in range(repeats * pairs):
        reads = reads_floor_steps_per_s(CYCLES, clock=time.thread_time)
        twin = _timed_pick_place(clock=time.thread_time)
        costs.append((1 / twin - 1 / reads) * 1e6)
    return statistics.median(costs)


def _idle_rate() -> float:
    """steps/s of twin.step() with nothing commanded: Frame building and the suction rule."""
    twin = Twin(TwinConfig())
    try:
        t0 = time.perf_counter()
        twin.step(IDLE_STEPS)
        return IDLE_STEPS / (time.perf_counter() - t0)
    finally:
        twin.close()


def _build_ms() -> float:
    t0 = time.perf_counter()
    twin = Twin(TwinConfig())
    elapsed = time.perf_counter() - t0
    twin.close()
    return elapsed * 1000.0


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(5, int(ctx.repeats))  # a 2-cycle run is short (~0.1 s): take a few more samples
    physics = ctx.physics_steps_per_s
    steps = pick_place_steps()
    run_rate = statistics.median(_timed_pick_place() for _ in range(repeats))
    idle_rate = statistics.median(_idle_rate() for _ in range(repeats))
    build_ms = statistics.median(_build_ms() for _ in range(repeats))
    sim_s = steps * TwinConfig().dt_ns * 1e-9
    ctx.rate_figures("twin", run_rate)
    cost_us = ctx.figures["twin_cost_us_per_step"] = twin_cost_us_per_step(repeats)
    return [
        (
            f"pick_place {CYCLES} cycles, no recording: steps/s (ratio to physics-only)",
            ctx.ratio(run_rate),
        ),
        (
            "pick_place: steps, simulated s, real-time factor",
            f"{steps}, {sim_s:.2f} s, {run_rate * TwinConfig().dt_ns * 1e-9:.0f}x",
        ),
        (
            "twin cost per step over the same motion's stepSimulation (pick_place)",
            f"{(1 / run_rate - 1 / (ctx.motion_physics_steps_per_s or physics)) * 1e6:.1f} us",
        ),
        (
            "twin cost per step over the reads floor (the same motion and a Frame's engine reads)",
            f"{cost_us:.2f} us (thread CPU, median of {repeats * PAIRS} pairs)",
        ),
        (
            "twin.step() idle: steps/s (ratio to physics-only)",
            f"{idle_rate:,.0f} ({idle_rate / physics:.2f}x)",
        ),
        ("building a Twin (connect, URDF, scene)", f"{build_ms:.1f} ms"),
    ]


if __name__ == "__main__":
    from bench import main  # tools/ is sys.path[0] when run as a script

    sys.exit(main(["--only", "twin", *sys.argv[1:]]))
