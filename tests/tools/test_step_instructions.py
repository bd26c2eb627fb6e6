"""tools/step_instructions.py: the runs it has valgrind count, and its answer without valgrind.
(The counting itself takes minutes under valgrind; README's figures come from it.)"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[2] / "tools"
SCRIPT = TOOLS / "step_instructions.py"
sys.path.insert(0, str(TOOLS))

import step_instructions
from bench import motion_actions


def _child(mode: str, folder: Path) -> int:
    done = subprocess.run([sys.executable, str(SCRIPT), "--child", mode, "1", str(folder)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split()[1])


def test_the_physics_run_replays_the_twins_motion_step_for_step(tmp_path):
    (tmp_path / "actions1.pkl").write_bytes(pickle.dumps(motion_actions(1)))
    steps = {mode: _child(mode, tmp_path) for mode in ("physics", "alone", "mcap")}
    assert steps["physics"] == steps["alone"] == steps["mcap"] > 1000
    assert (tmp_path / "mcap1.mcap").stat().st_size > 10_000


def test_a_step_is_the_difference_of_two_runs(tmp_path):
    out = tmp_path / "callgrind.out.1"
    out.write_text("events: Ir\nfn=main\n1 5\ntotals: 123456\n")
    assert step_instructions.callgrind_total(out) == 123456
    assert step_instructions.per_step({2: (1_000_000, 2000), 4: (1_900_000, 4000)}) == 450.0


def test_without_valgrind_it_says_so_in_one_line(tmp_path):
    done = subprocess.run(
        [sys.executable, str(SCRIPT)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=dict(os.environ, PATH=str(tmp_path)),
    )
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "valgrind is not installed" in done.stderr
