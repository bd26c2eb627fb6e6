"""`twin info` says what the run was (robot, objects with mass and pose, pad limits, task and
parameters) and, with --events, every event with its time and data."""

from __future__ import annotations

from pathlib import Path

from support.cli import twin

from twin.tasks import pick_place, task_identity

BREAK_GOLDEN = Path(__file__).resolve().parents[3] / "recordings" / "pick_place_break_mtb.mcap"


def test_info_shows_the_setup_of_the_break_golden(capsys):
    code, out, err = twin(capsys, "info", BREAK_GOLDEN)
    assert code == 0, err
    assert "  robot mtb: links 0.467 + 0.4005 m, Z stroke 0.2 m" in out
    assert "  object box: 0.5 kg, 0.05 x 0.05 x 0.05 m, at (0.2, 0.7, 0.025) m, yaw 0 deg" in out
    assert "  pad: breaks past pull 3 N, shear 1 N, peel 0.1 N·m" in out
    assert '  task pick_place (task), parameters {"cycles": 1}' in out
    assert "all events" not in out  # only with --events


def test_info_events_lists_every_event_with_time_and_data(capsys):
    code, out, _ = twin(capsys, "info", BREAK_GOLDEN, "--events")
    assert code == 0
    lines = out.split("all events (6):\n", 1)[1].splitlines()
    assert len(lines) == 6
    assert lines[3].split() == [
        "t=",
        "2.263",
        "s",
        "step",
        "543",
        "attach",
        "box",
        "suction",
        "attached",
    ]
    assert "break" in lines[4] and "shear 3.996 N > max_shear_force 1.0 N" in lines[4]
    identity = task_identity(pick_place.run)  # the task by its content
    assert lines[0].endswith(f'task_start            {identity} {{"cycles": 1}}'), lines[0]
