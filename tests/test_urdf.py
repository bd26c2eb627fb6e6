"""A user's robot: a URDF whose links are binary STL meshes (in millimetres, as the reports exported
them from Onshape) plus a small profile file naming its joints. The twin must load it, derive the
SCARA geometry from it, move the pad where asked and run pick_place on it."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from twin.cli import main
from twin.errors import ConfigError
from twin.model.config import TwinConfig
from twin.robot.profile_files import get_profile
from twin.robot.urdf import mesh_paths, urdf_text
from twin.sim.twin import Twin
from twin.sim.world import pb

SHOULDER_Z_M, ELBOW_DZ_M, LINK1_M, LINK2_M = 0.152, 0.05, 0.467, 0.4005
PAD_ABOVE_Z_JOINT_M, PAD_LENGTH_M = 0.065, 0.012
JOINTS = {"shoulder": "shoulder_yaw", "elbow": "elbow_yaw", "z": "quill_z", "wrist": "tool_yaw"}


def write_box_stl(path: Path, lo_mm: tuple[float, float, float], hi_mm: tuple[float, float, float]) -> None:
    """A closed box as a binary STL: 80-byte header, triangle count, 50 bytes per triangle."""
    (x0, y0, z0), (x1, y1, z1) = lo_mm, hi_mm
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    faces = [  # (normal, two triangles as vertex indices, counter-clockwise seen from outside)
        ((0, 0, -1), (0, 2, 1), (0, 3, 2)), ((0, 0, 1), (4, 5, 6), (4, 6, 7)),
        ((0, -1, 0), (0, 1, 5), (0, 5, 4)), ((0, 1, 0), (3, 7, 6), (3, 6, 2)),
        ((-1, 0, 0), (0, 4, 7), (0, 7, 3)), ((1, 0, 0), (1, 2, 6), (1, 6, 5)),
    ]
    out = bytearray(b"twin test mesh, millimetres".ljust(80, b" "))
    out += struct.pack("<I", 2 * len(faces))
    for normal, *tris in faces:
        for tri in tris:
            out += struct.pack("<3f", *normal)
            for i in tri:
                out += struct.pack("<3f", *v[i])
            out += struct.pack("<H", 0)
    path.write_bytes(bytes(out))


def _link(name: str, mesh: str, mass: float, com: tuple[float, float, float], inertia: tuple[float, ...]) -> str:
    geom = f'<geometry><mesh filename="meshes/{mesh}" scale="0.001 0.001 0.001"/></geometry>'
    return (f'<link name="{name}"><inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/><mass value="{mass}"/>'
            f'<inertia ixx="{inertia[0]}" ixy="0" ixz="0" iyy="{inertia[1]}" iyz="0" izz="{inertia[2]}"/></inertial>'
            f"<visual>{geom}</visual><collision>{geom}</collision></link>\n")


def _joint(name: str, kind: str, parent: str, child: str, xyz: tuple[float, float, float], axis: str,
           lower: float, upper: float, effort: float, velocity: float) -> str:
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="0 0 0"/><axis xyz="{axis}"/>'
            f'<limit lower="{lower}" upper="{upper}" effort="{effort}" velocity="{velocity}"/></joint>\n')


def write_user_robot(folder: Path, *, suction_signal: str = "vacuum") -> Path:
    """An MTB-like SCARA made of STL boxes; returns the profile file's path."""
    meshes = folder / "meshes"
    meshes.mkdir(parents=True)
    write_box_stl(meshes / "base.stl", (-90, -90, 0), (90, 90, 152))
    write_box_stl(meshes / "arm1.stl", (-40, -40, 0), (507, 40, 50))
    write_box_stl(meshes / "arm2.stl", (-40, -40, 0), (440.5, 40, 40))
    write_box_stl(meshes / "quill.stl", (-12, -12, 65), (12, 12, 365))
    write_box_stl(meshes / "cup.stl", (-20, -20, -12), (20, 20, 0))
    lim = math.radians(160), math.radians(150)
    urdf = "".join([
        '<?xml version="1.0"?>\n<robot name="stl_scara">\n',
        _link("base", "base.stl", 10.0, (0, 0, 0.076), (0.04, 0.04, 0.04)),
        _joint(JOINTS["shoulder"], "revolute", "base", "arm1", (0, 0, SHOULDER_Z_M), "0 0 1", -lim[0], lim[0], 60, 3),
        _link("arm1", "arm1.stl", 1.5, (0.2335, 0, 0.025), (0.0011, 0.037, 0.0376)),
        _joint(JOINTS["elbow"], "revolute", "arm1", "arm2", (LINK1_M, 0, ELBOW_DZ_M), "0 0 1", -lim[1], lim[1], 60, 3),
        _link("arm2", "arm2.stl", 1.0, (0.2, 0, 0.02), (0.0007, 0.02, 0.0205)),
        _joint(JOINTS["z"], "prismatic", "arm2", "quill", (LINK2_M, 0, 0), "0 0 -1", 0, 0.2, 60, 0.5),
        _link("quill", "quill.stl", 0.37, (0, 0, 0.215), (0.0028, 0.0028, 0.00003)),
        _joint(JOINTS["wrist"], "revolute", "quill", "tool0", (0, 0, PAD_ABOVE_Z_JOINT_M), "0 0 1",
               -math.pi, math.pi, 60, 3),
        _link("tool0", "cup.stl", 0.05, (0, 0, 0), (7.4e-6, 7.4e-6, 1e-5)),
        "</robot>\n",
    ])
    (folder / "stl_scara.urdf").write_text(urdf)
    joints = "\n".join(f'{role} = "{name}"' for role, name in JOINTS.items())
    profile = folder / "stl_scara.toml"
    profile.write_text(f'name = "stl_scara"\nurdf = "stl_scara.urdf"\npad_link = "tool0"\n'
                       f'suction_signal = "{suction_signal}"\npad_length_m = {PAD_LENGTH_M}\n\n[joints]\n{joints}\n')
    return profile


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
    assert p.tip_z0_m == pytest.approx(SHOULDER_Z_M + ELBOW_DZ_M + PAD_ABOVE_Z_JOINT_M - PAD_LENGTH_M)
    assert p.z_stroke_m == 0.2
    assert p.shoulder_limit_rad == pytest.approx(math.radians(160))
    assert p.suction_signals[0] == "vacuum"
    assert p.pad_link == "tool0"
    assert Path(p.urdf_path).is_file()
    assert urdf_text(p) == Path(p.urdf_path).read_text()
    assert [m.name for m in mesh_paths(p)] == ["arm1.stl", "arm2.stl", "base.stl", "cup.stl", "quill.stl"]
    assert all(m.is_file() for m in mesh_paths(p))
    # any variant's names still find the user's joints
    assert p.joint_index("/MTB_axis1") == 0 and p.joint_index("quill_z") == 2


def test_the_stl_meshes_are_loaded_and_scaled_from_millimetres(user_robot):
    twin = Twin(TwinConfig(profile=get_profile(str(user_robot))))
    try:
        w = twin.world
        arm1 = w.joints[0]
        lo, hi = pb.getAABB(w.robot, arm1, physicsClientId=w.client)
        assert hi[0] - lo[0] == pytest.approx(0.547, abs=0.01)  # 507 + 40 mm: the mesh, not a default shape
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
        w = twin.world
        root = pb.getLinkState(w.robot, w.pad_link, computeForwardKinematics=1, physicsClientId=w.client)[4]
        assert math.hypot(root[0] - x, root[1] - y) < 1e-4
        assert root[2] - PAD_LENGTH_M == pytest.approx(z, abs=1e-4)
    finally:
        twin.close()


def test_twin_run_pick_place_works_with_the_user_robot(user_robot, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = main(["run", "pick_place", "--robot", str(user_robot), "--cycles", "2"])  # records by default
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err == ""
    assert (tmp_path / "runs" / "pick_place_stl_scara.mcap").stat().st_size > 0
    assert "robot stl_scara:" in out
    assert "attach 2" in out and "release 2" in out and "placed 2" in out
    worst_mm = float(out.split("placement error: worst ")[1].split(" mm")[0])
    assert worst_mm < 5.0


@pytest.mark.parametrize("edit, expected", [
    (lambda t: t.replace('pad_link = "tool0"\n', ""), "lacks 'pad_link'"),
    (lambda t: t.replace('wrist = "tool_yaw"', ""), "joints lacks ['wrist']"),
    (lambda t: t.replace('quill_z"', 'quill_q"'), "has no joint named 'quill_q'"),
    (lambda t: t.replace('"tool0"', '"cup0"'), "has no link named 'cup0'"),
    (lambda t: t.replace('"stl_scara.urdf"', '"missing.urdf"'), "missing.urdf' does not exist"),
    (lambda t: t + "[[[", "cannot read robot profile"),
])
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
