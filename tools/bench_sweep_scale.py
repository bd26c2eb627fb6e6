"""Benchmark section: a sweep's size does not cost memory or a slow start, and Ctrl-C stops it.

For 100k, 1M and 10M planned scenarios (pick_place, one cycle, the box jittered; --save none, 2
local workers), `twin sweep` runs as a command; this section measures the time to its first
result (the journal's first row), the parent's peak resident memory (VmHWM) until then plus two
seconds, and how long it takes to end after SIGINT (Ctrl-C), its results written. The ratios
10M over 100k say whether either grows with the planned size (flat: about 1).
tools/bench.py calls bench(ctx); `python tools/bench_sweep_scale.py` runs it alone.
"""

from __future__ import annotations

import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SIZES = (100_000, 1_000_000, 10_000_000)
RUN_AFTER_FIRST_S = 2.0
STOP_LIMIT_S = 60.0  # a sweep that takes longer to stop is reported as hung (the goal is seconds)


def _peak_rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def measure(scenarios: int, folder: Path) -> tuple[float, float, float]:
    """(seconds to the first result, parent's peak MB, seconds from SIGINT to exit) of one sweep."""
    folder.mkdir(exist_ok=True)
    out = folder / f"s{scenarios}"
    journal = out / "journal.jsonl"
    cmd = [
        sys.executable,
        "-m",
        "twin",
        "sweep",
        "pick_place",
        "--scenarios",
        str(scenarios),
        "--vary",
        "box.x_m=uniform(0.19,0.21)",
        "--param",
        "cycles=1",
        "--save",
        "none",
        "--quiet",
        "-j",
        "2",
        "--out",
        str(out),
    ]
    t0 = time.perf_counter()
    # Ctrl-C as in a terminal
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # noqa: PLW1509
    )
    try:
        first_s = None
        while first_s is None and proc.poll() is None:
            if journal.exists() and journal.read_bytes().count(b"\n") >= 2:
                first_s = time.perf_counter() - t0
            else:
                time.sleep(0.01)
        time.sleep(RUN_AFTER_FIRST_S)
        peak_mb = _peak_rss_mb(proc.pid)
        t1 = time.perf_counter()
        proc.send_signal(signal.SIGINT)
        proc.wait(STOP_LIMIT_S)
        stop_s = time.perf_counter() - t1
        if not (out / "summary.json").exists():
            last = proc.stderr.read().decode(errors="replace").strip().splitlines()[-1:]
            raise RuntimeError(f"the sweep of {scenarios} wrote no summary after Ctrl-C: {last}")
        return first_s or float("nan"), peak_mb, stop_s
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def bench(ctx) -> list[tuple[str, str]]:
    rows, figures = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in SIZES:
            runs = [measure(n, Path(tmp) / f"r{k}") for k in range(ctx.repeats)]
            first, peak, stop = (statistics.median(r[i] for r in runs) for i in range(3))
            figures[n] = (first, peak, stop)
            label = (
                f"{n:,} planned scenarios: first result, parent's peak memory, stop after "
                f"Ctrl-C (medians of {ctx.repeats})"
            )
            rows.append((label, f"{first:.2f} s, {peak:.0f} MB, {stop:.2f} s"))
    small, large = figures[SIZES[0]], figures[SIZES[-1]]
    rows.append(
        (
            "10M over 100k: time to first result, peak memory (goal: about 1)",
            f"{large[0] / small[0]:.2f}x, {large[1] / small[1]:.2f}x",
        )
    )
    ctx.figures.update(
        sweep_first_result_s_10m=large[0],
        sweep_peak_mb_10m=large[1],
        sweep_stop_s_10m=large[2],
        sweep_first_result_10m_vs_100k=large[0] / small[0],
        sweep_peak_mb_10m_vs_100k=large[1] / small[1],
    )
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench import run

    sys.exit(run(["sweep_scale"], repeats=3))
