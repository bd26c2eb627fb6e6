"""Long pick_place runs: placements stay within 2 mm, and a miss fails loudly at the first one.

Real runs through the real twin (PyBullet) and the real CLI. Before the fix a 200-cycle run drifted
about 0.1 mm per cycle (28 mm at cycle 170), then picked nothing while still reporting `placed`
and exiting 0.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

import twin
from twin.model.config import SceneObject, SuctionParams, TwinConfig
from twin.model.errors import TaskError
from twin.model.profiles import PROFILES
from twin.record.mcap import schemas as S
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task
from twin.tasks.pick_place import POINT_A_M

pytestmark = pytest.mark.slow  # seconds each: `-m "not slow"` leaves them out

MAX_ERROR_M = 0.002
# What the twin gives now (README): at most 0.1 um of placement drift and 0.0002 deg of yaw per
# cycle.
DRIFT_LIMIT_M_PER_CYCLE = 1e-6  # ten times the measured drift
YAW_LIMIT_RAD_PER_CYCLE = math.radians(0.002)
# A task file that first carries the box off pick_place's pick point, so its first pick finds
# nothing.
MOVED_BOX_TASK = """
from twin.tasks import pick_place

def run(twin, cycles=1):
    twin.move_to(0.2, 0.7)
    twin.suction(True)
    twin.lower()
    twin.raise_()
    twin.move_to(0.5, 0.0)
    twin.lower()
    twin.suction(False)
    twin.raise_()
    pick_place.run(twin, cycles=cycles)
"""


class _Events:
    """A sink keeping only the events (a long run's frames are not needed)."""

    def __init__(self) -> None:
        self.events = []

    def on_frame(self, frame) -> None:
        pass

    def on_command(self, command) -> None:
        pass

    def on_event(self, event) -> None:
        self.events.append(event)


def _placed(robot: str, cycles: int, **params) -> list:
    sink = _Events()
    t = Twin(TwinConfig(profile=PROFILES[robot]), sinks=[sink])
    try:
        run_task(t, TASKS["pick_place"], {"cycles": cycles, **params})
    finally:
        t.close()
    kinds = [
        e.kind
        for e in sink.events
        if e.kind in ("attach", "release", "placed", "suction_empty", "break")
    ]
    assert kinds == ["attach", "release", "placed"] * cycles
    return [e for e in sink.events if e.kind == "placed"]


@pytest.mark.parametrize("robot", sorted(PROFILES))
def test_fifty_cycles_drift_under_a_micrometre_per_cycle(robot):
    placed = _placed(robot, 50)
    errors_m = [e.data["error_m"] for e in placed]
    assert max(errors_m) < MAX_ERROR_M / 20, errors_m  # 0.1 mm; measured 0.005 mm
    assert errors_m[-1] - errors_m[0] < 49 * DRIFT_LIMIT_M_PER_CYCLE, errors_m
    assert abs(placed[-1].data["yaw_rad"]) < 50 * YAW_LIMIT_RAD_PER_CYCLE


def test_twin_run_200_cycles_keeps_every_placement_within_2_mm(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "run", "pick_place", "--cycles", "200", "--no-record"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    worst = re.search(r"placement error: worst ([\d.]+) mm over 200 cycle\(s\)", done.stdout)
    # the worst placement stays far inside the task's 2 mm limit: 0.1 mm, as the 500-cycle
    # in-process run held (measured 0.045 mm there; it took 64 s of the suite and is gone)
    assert worst and float(worst.group(1)) < MAX_ERROR_M / 20 * 1e3, done.stdout[-2000:]
    assert "suction_empty" not in done.stdout


@pytest.mark.parametrize("drop_m", [0.0, 0.0005, 0.002])
def test_a_box_set_on_the_floor_stays_where_it_lands(drop_m):
    """The floor and solver settings: no landing slide (0.03-0.2 mm on a plane) and no creep at rest
    (0.2-0.5 mm and 0.3 degrees in 40 s with PyBullet's default solver residual)."""
    start = (0.5, 0.3, 0.025 + drop_m)
    t = Twin(TwinConfig(objects=(SceneObject("box", pos_m=start),)))
    t.step(240)
    landed = t.object_pose("box")
    t.step(40 * 240)
    rest = t.object_pose("box")
    t.close()
    assert math.hypot(landed[0] - start[0], landed[1] - start[1]) < 1e-6  # measured 0.04 um
    assert math.hypot(rest[0] - landed[0], rest[1] - landed[1]) < 5e-6  # measured 1.6 um
    assert abs(rest[2] - 0.025) < 2e-5
    assert abs(2 * math.atan2(rest[5], rest[6])) < math.radians(0.02)  # measured 0.004 degrees


def _moved_box_twin(sink) -> Twin:
    """The default scene but the box 60 mm off pick_place's first pick point (out of the pad's
    ray)."""
    box = SceneObject("box", pos_m=(POINT_A_M[0] + 0.06, POINT_A_M[1], 0.025))
    return Twin(TwinConfig(objects=(box,)), sinks=[sink])


def test_a_pick_that_senses_nothing_fails_the_task_naming_the_cycle():
    sink = _Events()
    t = _moved_box_twin(sink)
    with pytest.raises(TaskError) as err:
        run_task(t, TASKS["pick_place"], {"cycles": 3})
    assert str(err.value) == "cycle 1: suction on at (0.2, 0.7), nothing sensed"
    assert err.value.exit_code == 1
    kinds = [e.kind for e in sink.events if e.kind != "phase"]
    assert kinds == ["task_start", "suction_empty", "task_error"]  # no placed, no cycle 2
    assert t.frame.pad_pose[2] > 0.2  # the pad was raised before the task failed
    t.close()


def test_a_hold_that_breaks_at_the_pick_fails_the_task_and_places_nothing():
    """The break golden's scene: a 0.5 kg box on the stock finite-strength pad."""
    sink = _Events()
    heavy = TwinConfig(
        objects=(SceneObject("box", mass_kg=0.5),), suction=SuctionParams(infinite_strength=False)
    )
    t = Twin(heavy, sinks=[sink])
    with pytest.raises(TaskError, match=r"^cycle 1: suction on at \(0\.2, 0\.7\), the hold broke$"):
        run_task(t, TASKS["pick_place"], {"cycles": 1})
    assert [e.kind for e in sink.events if e.kind != "phase"] == [
        "task_start",
        "attach",
        "break",
        "task_error",
    ]
    t.close()


def test_keep_going_records_each_failed_cycle_and_places_nothing():
    sink = _Events()
    t = _moved_box_twin(sink)
    run_task(t, TASKS["pick_place"], {"cycles": 2, "keep_going": True})
    failed = [e for e in sink.events if e.kind == "cycle_failed"]
    assert [e.data["cycle"] for e in failed] == [1, 2]
    assert failed[1].message == "cycle 2: suction on at (-0.3, -0.55), nothing sensed"
    assert not [e for e in sink.events if e.kind in ("placed", "attach", "release")]
    assert sink.events[-1].kind == "task_end"
    t.close()


def test_a_placement_beyond_the_limit_fails_after_reporting_it():
    sink = _Events()
    t = Twin(TwinConfig(), sinks=[sink])
    with pytest.raises(
        TaskError, match=r"^cycle 1: placed 0\.\d{3,} mm from \(-0\.3, -0\.55\), beyond 1e-06 mm$"
    ):
        run_task(t, TASKS["pick_place"], {"cycles": 2, "max_error_m": 1e-9})
    assert [e.kind for e in sink.events if e.kind not in ("phase",)] == [
        "task_start",
        "attach",
        "release",
        "placed",
        "task_error",
    ]
    t.close()


def test_twin_run_exits_1_at_the_first_miss_and_records_outcome_error(tmp_path):
    task = tmp_path / "moved_box.py"
    task.write_text(MOVED_BOX_TASK)
    out = tmp_path / "miss.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "twin.cli", "run", str(task), "--cycles", "3", "--record", str(out)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 1
    assert done.stderr == "twin: error: cycle 1: suction on at (0.2, 0.7), nothing sensed\n"
    assert "placed" not in done.stdout
    rec = twin.load(out)
    assert rec.finalized and rec.meta[S.META_FINALIZED]["outcome"] == "error"
    assert [e.kind for e in rec.events if e.kind in ("suction_empty", "placed", "task_error")] == [
        "suction_empty",
        "task_error",
    ]
    assert Path(out).stat().st_size > 0
