"""Benchmark section: what a diff costs next to recording the run.

Records a long pick_place run (about 10 simulated minutes) twice to MCAP, then times `twin diff`'s
work on the two files — load both + compare + render the report — as a ratio to the wall time it
took to record one. Target: diffing takes at most a quarter of the recording time. It also runs
`twin replay` on the long recording in a process of its own: wall time and peak memory (RSS).
tools/bench.py calls bench(ctx); `python tools/bench_diff.py` runs it alone.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from twin.compare.engine import compare
from twin.compare.report import render_text
from twin.compare.tolerances import Tolerances
from twin.model.config import SceneObject, TwinConfig
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.verify.check import record_task

SIM_MINUTES = 10.0
CYCLE_S = 4.4  # simulated seconds per pick_place cycle with the mtb profile at 240 Hz
TARGET_RATIO = 0.25


def record(path: Path, config: TwinConfig, cycles: int) -> tuple[float, int]:
    """Record pick_place to path: (wall seconds, frames)."""
    params = {"cycles": cycles}
    t0 = time.perf_counter()
    with open_recorders(
        config, {"source": "task", "task": "pick_place", "params": params}, mcap_path=path
    ) as sinks:
        rec = record_task(config, "pick_place", params, sinks=sinks)
    return time.perf_counter() - t0, len(rec.frames)


def diff_once(golden: Path, candidate: Path, tolerance: str) -> tuple[float, float, float, bool]:
    """(load s, compare + report s, total s, match) for one `twin diff` of two files."""
    t0 = time.perf_counter()
    g, c = load(golden), load(candidate)
    t1 = time.perf_counter()
    result = compare(g, c, Tolerances.from_preset(tolerance))
    render_text(result)
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1, t2 - t0, result.match


_REPLAY_AND_REPORT_RSS = (
    "import resource, sys\n"
    "from twin.cli import main\n"
    "code = main(['replay', sys.argv[1]])\n"
    "print('peak_rss_kib', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n"
    "sys.exit(code)\n"
)


def replay_in_child(path: Path) -> tuple[float, float]:
    """`twin replay PATH` in a fresh process: (wall seconds, that process's peak resident memory in
    MB)."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _REPLAY_AND_REPORT_RSS, str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    wall_s = time.perf_counter() - t0
    peak = [
        line.split()[1] for line in done.stderr.splitlines() if line.startswith("peak_rss_kib ")
    ]
    if done.returncode != 0 or not peak:
        raise RuntimeError(
            f"twin replay failed ({done.returncode}): {done.stdout[-300:]}{done.stderr[-300:]}"
        )
    return wall_s, int(peak[0]) / 1024  # Linux reports KiB


def bench(ctx) -> list[tuple[str, str]]:
    cycles = int(SIM_MINUTES * 60 / CYCLE_S) + 1
    with tempfile.TemporaryDirectory(prefix="twin_bench_diff_") as tmp:
        folder = Path(tmp)
        config = TwinConfig()
        shifted = TwinConfig(objects=(SceneObject("box", pos_m=(0.201, 0.7, 0.025)),))
        rec_s, frames = record(folder / "golden.mcap", config, cycles)
        rec2_s, _ = record(folder / "again.mcap", config, cycles)
        record(folder / "shifted.mcap", shifted, cycles)
        record_s = statistics.median([rec_s, rec2_s])
        size_mb = (folder / "golden.mcap").stat().st_size / 1e6
        same = [
            diff_once(folder / "golden.mcap", folder / "again.mcap", "exact")
            for _ in range(ctx.repeats)
        ]
        replay_s, replay_mb = replay_in_child(folder / "golden.mcap")
        other = [
            diff_once(folder / "golden.mcap", folder / "shifted.mcap", "physical")
            for _ in range(ctx.repeats)
        ]
    assert all(s[3] for s in same) and not any(o[3] for o in other), (
        "bench runs did not diff as expected"
    )
    load_s = statistics.median(s[0] for s in same)
    cmp_s = statistics.median(s[1] for s in same)
    diff_s = statistics.median(s[2] for s in same)
    diff_other_s = statistics.median(o[2] for o in other)
    ratio = diff_s / record_s
    verdict = "meets" if ratio <= TARGET_RATIO else "MISSES"
    sim_min = frames * config.dt_s / 60
    return [
        (
            "long run",
            (
                f"pick_place {cycles} cycles, {sim_min:.1f} simulated min, {frames:,} frames, "
                f"{size_mb:.1f} MB MCAP"
            ),
        ),
        ("record one run (MCAP)", f"{record_s:.2f} s"),
        ("load both files", f"{load_s:.3f} s ({2 * frames / load_s:,.0f} frames/s)"),
        ("compare + report", f"{cmp_s:.3f} s ({frames / cmp_s:,.0f} frame pairs/s)"),
        ("diff, identical runs (exact)", f"{diff_s:.3f} s"),
        ("diff, box 1 mm away (physical)", f"{diff_other_s:.3f} s"),
        ("diff time / record time", f"{ratio:.3f} ({verdict} the target of {TARGET_RATIO})"),
        (
            "twin replay of the long run: wall time, peak RSS",
            f"{replay_s:.2f} s, {replay_mb:.0f} MB",
        ),
    ]


if __name__ == "__main__":
    from bench import main  # tools/ is sys.path[0] when run as a script

    sys.exit(main(["--only", "diff", *sys.argv[1:]]))
