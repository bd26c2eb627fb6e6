"""tools/bench.py: the framework runs a section against the measured baseline and prints one table."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "tools" / "bench.py"


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH), *args], capture_output=True, text=True, timeout=120,
                          check=False)


def test_only_twin_prints_the_baseline_and_the_twins_ratio():
    done = _bench("--only", "twin", "--repeats", "1", "--physics-steps", "2000")
    assert done.returncode == 0, done.stderr
    rows = {tuple(c.strip() for c in line.split("|")[:2]): line.split("|")[2].strip()
            for line in done.stdout.splitlines() if line.count("|") == 2}
    physics = float(rows[("physics", "physics-only steps/s (median of 1)")].split()[0].replace(",", ""))
    assert physics > 0
    rate, ratio = re.match(r"([\d,]+) \(([\d.]+)x idle",
                           rows[("twin", "pick_place 2 cycles, no recording: steps/s (ratio to physics-only)")]).groups()
    assert abs(float(ratio) - float(rate.replace(",", "")) / physics) <= 0.006  # measured against that baseline
    motion = float(rows[("physics", "physics-only steps/s, pick_place's motion and holds (median)")].split()[0]
                   .replace(",", ""))
    assert physics > motion > 0  # a moving arm with contacts costs more than an idle one
    assert not any(section in ("record", "diff", "remote") for section, _ in rows)  # --only selected


def test_list_names_every_section_and_unknown_sections_are_refused():
    listed = _bench("--list").stdout.split()
    assert "twin" in listed and listed == sorted(listed)
    done = _bench("--only", "nope")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip().startswith("bench: error: unknown section 'nope'") and done.stderr.count("\n") == 1
