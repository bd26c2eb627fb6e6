"""Benchmark section: what recording costs.

pick_place run without recording, with MCAP, with MCAP + Rerun, each as a ratio to the
physics-only step rate; MCAP bytes per simulated minute; the recorder's cost per step; load time.
tools/bench.py calls bench(ctx); `python tools/bench_record.py` runs it alone.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from twin.model.config import TwinConfig
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task

CYCLES = 16
RUN = {"source": "task", "task": "pick_place", "params": {"cycles": CYCLES}}


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the recorder process)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed_run(folder: Path, *, mcap: bool, rrd: bool) -> tuple[int, float, float, int]:
    """One pick_place run: (steps, wall seconds, CPU seconds of this process's threads and of the
    recorder process it waited for, MCAP bytes)."""
    config = TwinConfig()
    mcap_path = folder / "bench.mcap" if mcap else None
    rrd_path = folder / "bench.rrd" if rrd else None
    t0, cpu0 = time.perf_counter(), _cpu_s()
    with open_recorders(config, RUN, mcap_path=mcap_path, rrd_path=rrd_path) as sinks:
        twin = Twin(config, sinks=sinks)
        run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
        twin.close()
    wall_s, cpu_s = time.perf_counter() - t0, _cpu_s() - cpu0
    return twin.step_index, wall_s, cpu_s, mcap_path.stat().st_size if mcap_path else 0


def recorder_cpu_us_per_frame(folder: Path, repeats: int) -> float:
    """Process CPU time the MCAP recorder spends per frame, fed a recorded run's frames (no physics)."""
    from twin.model.columns import FrameCollector
    from twin.record.mcap.writer import McapRecorder
    from twin.robot.urdf import urdf_text

    config = TwinConfig()
    collector = FrameCollector()
    twin = Twin(config, sinks=[collector])
    run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
    twin.close()
    best = float("inf")
    for _ in range(max(3, repeats)):
        t0 = time.process_time()
        recorder = McapRecorder(folder / "cpu.mcap", config, RUN, urdf=urdf_text(config.profile))
        for frame in collector.frames:
            recorder.on_frame(frame)
        for event in collector.events:
            recorder.on_event(event)
        recorder.close()
        best = min(best, time.process_time() - t0)
    return best / len(collector.frames) * 1e6


def _have_rerun_writer() -> bool:
    try:
        import twin.record.rerun.writer  # noqa: F401
    except ImportError:
        return False
    return True


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(1, int(ctx.repeats))
    modes = {"twin, no recording": (False, False), "twin + MCAP": (True, False)}
    if _have_rerun_writer():
        modes["twin + MCAP + Rerun"] = (True, True)
    rows: list[tuple[str, str]] = []
    rates: dict[str, float] = {}
    cpu_us: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="twin_bench_record_") as tmp:
        folder = Path(tmp)
        mcap_bytes, steps = 0, 0
        for name, (mcap, rrd) in modes.items():
            samples, cpu_samples = [], []
            for _ in range(repeats):
                steps, wall_s, cpu_s, size = timed_run(folder, mcap=mcap, rrd=rrd)
                samples.append(steps / wall_s)
                cpu_samples.append(cpu_s / steps * 1e6)
                mcap_bytes = size or mcap_bytes
            rates[name] = statistics.median(samples)
            cpu_us[name] = statistics.median(cpu_samples)
            rows.append((f"{name}: steps/s (ratio to physics-only)",
                         f"{ctx.ratio(rates[name])}; CPU {cpu_us[name]:.1f} us/step"))
        plain, with_mcap = rates["twin, no recording"], rates["twin + MCAP"]
        ctx.rate_figures("record_mcap", with_mcap)
        rows.append(("twin + MCAP: speed relative to no recording (wall; CPU)",
                     f"{with_mcap / plain:.2f}x; {cpu_us['twin, no recording'] / cpu_us['twin + MCAP']:.2f}x"))
        rows.append(("MCAP recorder cost per step (wall, in the run)", f"{(1 / with_mcap - 1 / plain) * 1e6:.2f} us"))
        if "twin + MCAP + Rerun" in rates:
            both = rates["twin + MCAP + Rerun"]
            ctx.rate_figures("record_both", both)
            rows.append(("twin + MCAP + Rerun: speed relative to no recording (wall; CPU)",
                         f"{both / plain:.2f}x; {cpu_us['twin, no recording'] / cpu_us['twin + MCAP + Rerun']:.2f}x"))
            rows.append(("MCAP + Rerun recorders cost per step (wall, in the run)",
                         f"{(1 / both - 1 / plain) * 1e6:.2f} us"))
        rows.append(("MCAP recorder CPU per frame (isolated, best of repeats)",
                     f"{recorder_cpu_us_per_frame(folder, repeats):.2f} us"))
        sim_min = steps * TwinConfig().dt_ns * 1e-9 / 60.0
        rows.append(("MCAP bytes per simulated minute", f"{mcap_bytes / sim_min / 1e6:.2f} MB"))
        ctx.figures["mcap_mb_per_sim_min"] = mcap_bytes / sim_min / 1e6
        t0 = time.perf_counter()
        recording = load(folder / "bench.mcap")
        load_s = time.perf_counter() - t0
        rows.append(("load() per simulated minute", f"{load_s / sim_min * 1000:.1f} ms ({len(recording.frames)} frames)"))
    return rows


def main() -> int:
    """Run this section alone, with bench.py's baselines."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench import main as bench_main

    return bench_main(["--only", "record"])


if __name__ == "__main__":
    sys.exit(main())
