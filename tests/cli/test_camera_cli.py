"""--camera for twin teleop and twin serve: their recordings hold the pictures, and replay them
exactly."""

from __future__ import annotations

import pytest
from support.server import ServerProcess

import twin
from twin.cli.main import main
from twin.pictures import track_rgb


def test_teleop_records_the_cameras_pictures(tmp_path, capsys):
    path = tmp_path / "teleop.mcap"
    code = main(
        [
            "teleop",
            "--keys",
            "d*3 wait",
            "--key-interval",
            "0.25",
            "--camera",
            "wrist",
            "--camera-size",
            "64x48",
            "--camera-hz",
            "8",
            "--record",
            str(path),
        ]
    )
    assert code == 0, capsys.readouterr().err
    rec = twin.load(path)
    track = rec.cameras["wrist"]
    assert (track.width_px, track.height_px) == (64, 48) and rec.config.cameras[0].rate_hz == 8.0
    assert list(track.step) == list(range(0, int(rec.frames.step[-1]) + 1, 30))  # 8 Hz at 240 Hz
    assert track_rgb(track, 0).shape == (48, 64, 3)
    capsys.readouterr()
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "MATCH (tolerance noise" in out and "  bit-identical\n" in out


@pytest.mark.slow
def test_serve_records_the_cameras_pictures(tmp_path):
    path = tmp_path / "remote.mcap"
    with ServerProcess(
        "--stepped", "--camera", "overhead", "--camera-size", "80x60", "--record", str(path)
    ) as server:
        sim = server.client().require("sim")
        sim.setStepping(True)
        sim.startSimulation()
        sim.setJointTargetPosition(sim.getObject("/MTB_axis1"), 0.5)
        for _ in range(100):
            sim.step()
        sim.stopSimulation()
        server.wait_for(r"recorded .*remote\.mcap", 30)
    rec = twin.load(path)
    track = rec.cameras["overhead"]
    assert len(track) == len(range(0, int(rec.frames.step[-1]) + 1, 16)) >= 7
    assert track.data[0] != track.data[-1]  # the arm turned
