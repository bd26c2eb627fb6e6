"""A user's robot: a URDF whose links are binary STL meshes (in millimetres, as the reports exported
them from Onshape) plus a small profile file naming its joints. The twin must load it, derive the
SCARA geometry from it, move the pad where asked and run pick_place on it."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from support.user_robot import (
    ELBOW_DZ_M,
    JOINTS,
    LINK1_M,
    LINK2_M,
    PAD_ABOVE_Z_JOINT_M,
    PAD_LENGTH_M,
    SHOULDER_Z_M,
    write_user_robot,
)

from twin.cli import main
from twin.model.config import TwinConfig
from twin.model.errors import ConfigError
from twin.robot.profile_files import get_profile
from twin.robot.urdf import mesh_paths, urdf_text
from twin.sim.twin import Twin
from twin.sim.world import pb


@pytest.fixture()
def user_robot(tmp_path) -> Path:
    return write_user_robot(tmp_path)


def test_profile_file_yields_the_geometry_of_the_urdf(user_robot):
    p = get_profile(str(user_robot))
    assert p.name == "stl_scara"
    assert p.joint_names == tuple(JOINTS.values())
    assert p.link1_m == pytest.approx(LINK1_M, abs=1e-12)
    assert p.link2_m == pytest.approx(LINK2_M, abs=1e-12)
    assert p.shoulder_height_m == pytest.approx(SHOULDER_Z_M)
    assert p.elbow_height_m == pytest.approx(SHOULDER_Z_M + ELBOW_DZ_M)
    assert p.tip_z0_m == pytest.approx(
        SHOULDER_Z_M + ELBOW_DZ_M + PAD_ABOVE_Z_JOINT_M - PAD_LENGTH_M
    )
    assert p.z_stroke_m == 0.2
    assert p.shoulder_limit_rad == pytest.approx(math.radians(160))
    assert p.suction_signals[0] == "vacuum"
    assert p.pad_link == "tool0"
    assert Path(p.urdf_path).is_file()
    assert urdf_text(p) == Path(p.urdf_path).read_text()
    assert [m.name for m in mesh_paths(p)] == [
        "arm1.stl",
        "arm2.stl",
        "base.stl",
        "cup.stl",
        "quill.stl",
    ]
    assert all(m.is_file() for m in mesh_paths(p))
    # any variant's names still find the user's joints
    assert p.joint_index("/MTB_axis1") == 0 and p.joint_index("quill_z") == 2


def test_the_stl_meshes_are_loaded_and_scaled_from_millimetres(user_robot):
    twin = Twin(TwinConfig(profile=get_profile(str(user_robot))))
    try:
        w = twin._world  # the engine, looked at directly (white-box)
        arm1 = w.joints[0]
        lo, hi = pb.getAABB(w.robot, arm1, physicsClientId=w.client)
        # 507 + 40 mm: the mesh, not a default shape
        assert hi[0] - lo[0] == pytest.approx(0.547, abs=0.01)
        assert hi[2] - lo[2] == pytest.approx(0.05, abs=0.01)
        assert pb.getDynamicsInfo(w.robot, arm1, physicsClientId=w.client)[0] == 1.5
    finally:
        twin.close()


@pytest.mark.parametrize("x_m, y_m", [(0.5, 0.3), (-0.4, 0.5), (-0.3, -0.55), (0.6, -0.2)])
def test_twin_moves_the_users_pad_to_the_point(user_robot, x_m, y_m):
    twin = Twin(TwinConfig(profile=get_profile(str(user_robot))))
    try:
        twin.move_to(x_m, y_m, heading_rad=0.3)
        twin.z_to(0.1)
        x, y, z = twin.pad_position()
        assert math.hypot(x - x_m, y - y_m) < 1e-3
        assert z == pytest.approx(0.1, abs=3e-4)
        # the simulated pad link agrees with the geometry the profile derived from the URDF
        w = twin._world  # the engine, looked at directly (white-box)
        root = pb.getLinkState(
            w.robot, w.pad_link, computeForwardKinematics=1, physicsClientId=w.client
        )[4]
        assert math.hypot(root[0] - x, root[1] - y) < 1e-4
        assert root[2] - PAD_LENGTH_M == pytest.approx(z, abs=1e-4)
    finally:
        twin.close()


def test_twin_run_pick_place_works_with_the_user_robot(user_robot, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # records by default
    code = main(["run", "pick_place", "--robot", str(user_robot), "--cycles", "2"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err == ""
    assert (tmp_path / "runs" / "pick_place_stl_scara.mcap").stat().st_size > 0
    assert "robot stl_scara:" in out
    assert "attach 2" in out and "release 2" in out and "placed 2" in out
    worst_mm = float(out.split("placement error: worst ")[1].split(" mm")[0])
    assert worst_mm < 5.0


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda t: t.replace('pad_link = "tool0"\n', ""), "lacks 'pad_link'"),
        (lambda t: t.replace('wrist = "tool_yaw"', ""), "joints lacks ['wrist']"),
        (lambda t: t.replace('quill_z"', 'quill_q"'), "has no joint named 'quill_q'"),
        (lambda t: t.replace('"tool0"', '"cup0"'), "has no link named 'cup0'"),
        (lambda t: t.replace('"stl_scara.urdf"', '"missing.urdf"'), "missing.urdf' does not exist"),
        (lambda t: t + "[[[", "cannot read robot profile"),
    ],
)
def test_bad_profile_files_are_one_line_errors(user_robot, capsys, edit, expected):
    user_robot.write_text(edit(user_robot.read_text()))
    with pytest.raises(ConfigError, match=expected.replace("[", r"\[").replace("]", r"\]")):
        get_profile(str(user_robot))
    assert main(["run", "pick_place", "--robot", str(user_robot), "--no-record"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error: ") and err.count("\n") == 1 and expected in err


def test_a_z_joint_pointing_up_is_refused(user_robot):
    urdf = user_robot.parent / "stl_scara.urdf"
    text = urdf.read_text()
    urdf.write_text(text.replace('<axis xyz="0 0 -1"/>', '<axis xyz="0 0 1"/>'))
    with pytest.raises(ConfigError, match="expected axis '0 0 -1'"):
        get_profile(str(user_robot))
