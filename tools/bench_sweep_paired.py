"""Benchmark section: the cost of a paired check (twin.sweep.paired) at 10k and 100k scenarios.

Two results.parquet files with a sweep's columns (scenario, seed, three varied keys, outcome,
error, placement_error_mm, the event counts, sim_s, wall_s) are written: a reference with 5 %
failures and a new run where 1 % of the scenarios flip (most of them ok -> failed) and every
placement moves a little. The numbers are drawn (numpy, fixed seed), not simulated: what is
measured is the check, which reads columns and never the physics. A fresh process reads both
files, pairs them and renders the report; its wall time after the imports (median over repeats)
and its peak resident memory (VmHWM: the whole process with its imports, about 72 MB of them) are
reported. `python tools/bench_sweep_paired.py` runs it alone.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

SIZES = (10_000, 100_000)
CHILD = """
import json, sys, time
from twin.sweep import paired
t0 = time.perf_counter()  # after the imports: the check itself
a = paired.read_side(sys.argv[1]); b = paired.read_side(sys.argv[2])
p = paired.pair(a, b)
text = paired.report_text(p, "sweep.toml")
seconds = time.perf_counter() - t0
peak = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:"))
print(json.dumps({"s": seconds, "peak_mb": peak / 1024, "worse": p.worse, "better": p.better}))
"""


def write_pair(folder: Path, n: int) -> tuple[Path, Path]:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(24)
    x, y = rng.normal(0.2, 0.012, n), rng.normal(0.7, 0.012, n)
    mass = rng.choice([0.1, 0.5], n)
    ok = rng.random(n) > 0.05
    flip = rng.random(n)
    ok_new = np.where(flip < 0.01, ~ok, ok)
    placement = np.abs(rng.normal(13.0, 7.0, n))
    paths = []
    for name, outcome, moved in (("a", ok, 0.0), ("b", ok_new, 0.05)):
        error = np.where(outcome, "", "cycle 1: suction on at (0.2, 0.7), nothing sensed")
        table = pa.table({
            "scenario": np.arange(n, dtype=np.int64), "seed": np.full(n, 2026, dtype=np.int64),
            "box.x_m": x, "box.y_m": y, "box.mass_kg": mass,
            "outcome": np.where(outcome, "ok", "error"), "error": error,
            "placement_error_mm": pa.array(placement + moved, mask=~outcome),
            **{k: np.ones(n, dtype=np.int64)
               for k in ("attach", "release", "break", "suction_empty")},
            "sim_s": np.full(n, 4.6), "wall_s": rng.random(n)})
        path = folder / f"{name}.parquet"
        pq.write_table(table, path)
        paths.append(path)
    return paths[0], paths[1]


def measure(n: int, repeats: int) -> tuple[float, float]:
    """(median seconds, peak MB) of a fresh process's paired check of n scenarios."""
    with tempfile.TemporaryDirectory() as tmp:
        a, b = write_pair(Path(tmp), n)
        runs = [json.loads(subprocess.run([sys.executable, "-c", CHILD, str(a), str(b)], check=True,
                                          capture_output=True, text=True).stdout)
                for _ in range(max(1, repeats))]
    return statistics.median(r["s"] for r in runs), max(r["peak_mb"] for r in runs)


def bench(ctx) -> list[tuple[str, str]]:
    rows = []
    for n in SIZES:
        seconds, peak = measure(n, ctx.repeats)
        rows.append((f"paired check of {n:,} scenarios (read, pair, report; fresh process)",
                     f"{seconds:.2f} s, peak {peak:.0f} MB"))
        if n == 10_000:
            ctx.figures.update(sweep_paired_check_s_per_10k=seconds,
                               sweep_paired_check_peak_mb=peak)
    return rows


if __name__ == "__main__":
    from types import SimpleNamespace

    ctx = SimpleNamespace(repeats=3, figures={})
    for label, value in bench(ctx):
        print(f"{label}: {value}")
    print(json.dumps(ctx.figures))
