"""pick_place_vision: it finds a box far off pick_place's fixed point (turned, too) in the overhead
picture, places it square on the target, and its recording holds the picture's part that the
decision used, from which the same decision is derived again; the file checks bit-identical."""

from __future__ import annotations

import dataclasses
import math

import pytest

from twin.cli.main import main
from twin.model.config import TwinConfig
from twin.model.errors import TaskError
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.sim.twin import Twin
from twin.tasks import pick_place, pick_place_vision, run_task
from twin.tasks.pick_place_vision import SeenPicture, locate
from twin.verify.check import task_run

PARAMS = {"cycles": 1, "pause_s": 0.1}
START = (0.26, 0.63, 0.4)  # 60 mm and 70 mm off pick_place's point, turned 23 degrees


def _config() -> TwinConfig:
    base = TwinConfig()
    box = dataclasses.replace(base.objects[0], pos_m=(START[0], START[1], 0.025), yaw_rad=START[2])
    return dataclasses.replace(base, objects=(box,))


def test_pick_place_misses_the_box_the_seeing_task_places(tmp_path):
    config = _config()
    twin = Twin(config)
    try:
        with pytest.raises(TaskError, match="nothing sensed"):
            run_task(twin, pick_place.run, PARAMS)
    finally:
        twin.close()

    path = tmp_path / "vision.mcap"
    with open_recorders(
        config, task_run("pick_place_vision", PARAMS, path), mcap_path=path, background=False
    ) as sinks:
        twin = Twin(config, sinks=list(sinks))
        try:
            run_task(twin, pick_place_vision.run, PARAMS)
        finally:
            twin.close()
    rec = load(str(path))
    assert rec.outcome == "ok"
    seen = [e for e in rec.events if e.kind == "seen"]
    placed = [e for e in rec.events if e.kind == "placed"]
    assert len(seen) == 1 and len(placed) == 1
    data = seen[0].data
    assert (
        data["found"] and abs(data["x_m"] - START[0]) < 1e-3 and abs(data["y_m"] - START[1]) < 1e-3
    )
    assert abs(data["yaw_rad"] - START[2]) < math.radians(1.0)
    assert abs(data["height_m"] - 0.05) < 1e-3 and data["pixels"] > 100
    assert placed[0].data["error_m"] < 0.002 and abs(placed[0].data["yaw_rad"]) < math.radians(1.0)

    again = locate(SeenPicture.from_event(data))  # the decision, from the file alone
    assert (again.x_m, again.y_m, again.yaw_rad, again.pixels) == (
        data["x_m"],
        data["y_m"],
        data["yaw_rad"],
        data["pixels"],
    )
    assert main(["check", "--tolerance", "exact", str(path)]) == 0


def test_a_box_beyond_the_arms_reach_fails_by_name(tmp_path, capsys):
    assert (
        main(
            [
                "run",
                "pick_place_vision",
                "--param",
                "cycles=1",
                "--param",
                "pause_s=0.1",
                "--record",
                str(tmp_path / "ok.mcap"),
            ]
        )
        == 0
    )
    assert "cycle 1: placed" in capsys.readouterr().out
    config = _config()
    far = dataclasses.replace(config.objects[0], pos_m=(0.2, 0.9, 0.025))
    twin = Twin(dataclasses.replace(config, objects=(far,)))
    try:
        with pytest.raises(Exception, match="outside the reach annulus"):
            run_task(twin, pick_place_vision.run, PARAMS)
    finally:
        twin.close()
