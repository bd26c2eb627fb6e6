"""Benchmark section: what `twin export` costs.

Records pick_place (10 cycles, about 45 simulated seconds) with the overhead camera, then times the
export of that file: frames to Parquet and to CSV (rows/s, load included), and to a LeRobot dataset
at 30 fps with its AV1 video (dataset frames/s) and without --verify's replay. Medians over repeats.
tools/bench.py calls bench(ctx); `python tools/bench_export.py` runs it alone.
"""

from __future__ import annotations

import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from twin.export.files import write_table
from twin.export.pipeline import export_lerobot
from twin.model.config import TwinConfig
from twin.model.images import camera
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.verify.check import record_task

CYCLES = 10
FPS = 30


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(1, int(ctx.repeats))
    with tempfile.TemporaryDirectory(prefix="twin_bench_export_") as tmp:
        folder = Path(tmp)
        mcap = folder / "run.mcap"
        config = TwinConfig(cameras=(camera("overhead"),))
        params = {"cycles": CYCLES}
        with open_recorders(
            config, {"source": "task", "task": "pick_place", "params": params}, mcap_path=mcap
        ) as sinks:
            record_task(config, "pick_place", params, sinks=sinks)
        frames = len(load(mcap).frames)
        parquet = statistics.median(
            _timed(lambda: write_table(load(mcap), folder / "f.parquet", "parquet"))
            for _ in range(repeats)
        )
        csv = statistics.median(
            _timed(lambda: write_table(load(mcap), folder / "f.csv", "csv")) for _ in range(repeats)
        )
        written = []

        def lerobot(verify: bool) -> None:
            out = folder / "ds"
            shutil.rmtree(out, ignore_errors=True)
            written.append(export_lerobot([str(mcap)], out, FPS, verify_first=verify)[0])

        plain = statistics.median(_timed(lambda: lerobot(False)) for _ in range(repeats))
        verified = statistics.median(_timed(lambda: lerobot(True)) for _ in range(repeats))
        ds_frames = written[-1].frames
        video_mb = sum(p.stat().st_size for p in (folder / "ds" / "videos").rglob("*.mp4")) / 1e6
    return [
        ("export input", f"pick_place {CYCLES} cycles, {frames:,} frames, overhead camera 320x240"),
        (
            "twin export --format parquet (load + write)",
            f"{parquet:.2f} s ({frames / parquet:,.0f} rows/s)",
        ),
        ("twin export --format csv (load + write)", f"{csv:.2f} s ({frames / csv:,.0f} rows/s)"),
        (
            f"twin export --format lerobot --fps {FPS} (AV1 video)",
            (
                f"{plain:.2f} s ({ds_frames / plain:,.0f} dataset frames/s, {ds_frames} "
                f"frames, video {video_mb:.2f} MB)"
            ),
        ),
        ("the same with --verify (replay first)", f"{verified:.2f} s"),
    ]


if __name__ == "__main__":
    from bench import main  # tools/ is sys.path[0] when run as a script

    sys.exit(main(["--only", "export", *sys.argv[1:]]))
