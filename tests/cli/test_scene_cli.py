"""`twin run --set KEY=VALUE` and `--scene FILE.toml`: the scene is recorded in the run's
configuration, replay and check rebuild it, diff names it, info lists it; bad input is one line,
exit 2, before anything runs."""

from __future__ import annotations

import pytest

import twin
from twin.cli.main import main

TWO_BOXES = """
[[box]]
name = "bottom"
size_m = [0.06, 0.06, 0.05]
mass_kg = 0.3
pos_m = [0.35, 0.45, 0.025]
rgba = [0.9, 0.4, 0.1, 1.0]

[[box]]
name = "top"
"""


def test_set_moves_the_box_and_replay_check_and_diff_see_it(tmp_path, capsys):
    moved, plain = tmp_path / "moved.mcap", tmp_path / "plain.mcap"
    run = ["run", "pick_place", "--cycles", "1", "--param", "pause_s=0.1"]
    assert main([*run, "--set", "box.x_m=0.201", "--set", "pad.max_pull_force_n=5",
                 "--record", str(moved)]) == 0
    assert main([*run, "--record", str(plain)]) == 0
    rec = twin.load(moved)
    assert rec.config.objects[0].pos_m == (0.201, 0.7, 0.025)
    assert rec.config.suction.max_pull_force_n == 5.0
    assert twin.load(plain).config.objects[0].pos_m == (0.2, 0.7, 0.025)
    assert abs(rec.frames.object_poses[0][0][0] - 0.201) < 1e-6  # the box starts there
    capsys.readouterr()
    assert main(["replay", str(moved), "--quiet"]) == 0
    assert main(["check", str(moved)]) == 0
    assert main(["diff", str(plain), str(moved)]) == 1
    out = capsys.readouterr().out
    assert "configuration differences: objects[0].pos_m [0.2, 0.7, 0.025] -> [0.201, 0.7, 0.025]" \
        in out and "suction.max_pull_force_n 3.0 -> 5.0" in out


def test_a_scene_file_with_two_boxes_is_recorded_and_listed(tmp_path, capsys):
    scene = tmp_path / "two.toml"
    scene.write_text(TWO_BOXES)
    path = tmp_path / "two.mcap"
    assert main(["run", "pick_place", "--cycles", "1", "--param", "box=top", "--scene", str(scene),
                 "--set", "top.mass_kg=0.2", "--record", str(path)]) == 0
    objects = twin.load(path).config.objects
    assert [o.name for o in objects] == ["bottom", "top"]
    assert objects[0].size_m == (0.06, 0.06, 0.05) and objects[1].mass_kg == 0.2
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "objects: bottom, top;" in out
    assert "object bottom: 0.3 kg, 0.06 x 0.06 x 0.05 m, at (0.35, 0.45, 0.025) m" in out
    assert "object top: 0.2 kg" in out
    assert main(["replay", str(path), "--quiet"]) == 0


@pytest.mark.parametrize(
    ("args", "scene", "message"),
    [
        (["--set", "bx.x_m=0.2"], None, "--set key 'bx.x_m' is unknown"),
        (["--set", "box.mass_kg=-1"], None, "--set box.mass_kg=-1: box.mass_kg = -1 is invalid"),
        (["--set", "box.x_m"], None, "--set 'box.x_m' is invalid; expected KEY=VALUE"),
        (["--set", "box.x_m=nan"], None, "--set box.x_m=nan is invalid"),
        (["--set", "task.cycles=1"], None, "task parameters go in --param cycles=VALUE"),
        (["--set", "box.x_m=0.2", "--set", "box.x_m=0.3"], None, "--set box.x_m is given twice"),
        ([], "[[box]]\nsize_m = [1, 1, 1]\n", "box 1 has no name"),
        ([], '[[box]]\nname = "a"\nmass_kg = 0\n', "box 1 (a).mass_kg = 0 is invalid"),
        ([], '[[box]]\nname = "a"\n[[box]]\nname = "a"\n', "names must be unique"),
        ([], '[[box]]\nname = "a"\ncolour = 1\n', "unknown field 'colour'"),
        ([], '[table]\nname = "a"\n', "unknown table 'table'"),
        ([], "", "holds no [[box]] tables"),
        ([], "[[box\n", "--scene"),
    ],
)
def test_bad_settings_and_scenes_are_one_line_exit_2(tmp_path, capsys, args, scene, message):
    if scene is not None:
        (tmp_path / "s.toml").write_text(scene)
        args = [*args, "--scene", str(tmp_path / "s.toml")]
    assert main(["run", "pick_place", "--record", str(tmp_path / "x.mcap"), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error: ") and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x.mcap").exists()
