"""A user's robot for tests: an MTB-like SCARA made of binary STL meshes in millimetres plus a
profile file naming its joints (the URDF tests build it; record, replay, rerun and verdict tests
load it)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

SHOULDER_Z_M, ELBOW_DZ_M, LINK1_M, LINK2_M = 0.152, 0.05, 0.467, 0.4005
PAD_ABOVE_Z_JOINT_M, PAD_LENGTH_M = 0.065, 0.012
JOINTS = {"shoulder": "shoulder_yaw", "elbow": "elbow_yaw", "z": "quill_z", "wrist": "tool_yaw"}


def write_box_stl(
    path: Path, lo_mm: tuple[float, float, float], hi_mm: tuple[float, float, float]
) -> None:
    """A closed box as a binary STL: 80-byte header, triangle count, 50 bytes per triangle."""
    (x0, y0, z0), (x1, y1, z1) = lo_mm, hi_mm
    v = [
        (x0, y0, z0),
        (x1, y0, z0),
        (x1, y1, z0),
        (x0, y1, z0),
        (x0, y0, z1),
        (x1, y0, z1),
        (x1, y1, z1),
        (x0, y1, z1),
    ]
    faces = [  # (normal, two triangles as vertex indices, counter-clockwise seen from outside)
        ((0, 0, -1), (0, 2, 1), (0, 3, 2)),
        ((0, 0, 1), (4, 5, 6), (4, 6, 7)),
        ((0, -1, 0), (0, 1, 5), (0, 5, 4)),
        ((0, 1, 0), (3, 7, 6), (3, 6, 2)),
        ((-1, 0, 0), (0, 4, 7), (0, 7, 3)),
        ((1, 0, 0), (1, 2, 6), (1, 6, 5)),
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


def _link(
    name: str, mesh: str, mass: float, com: tuple[float, float, float], inertia: tuple[float, ...]
) -> str:
    geom = f'<geometry><mesh filename="meshes/{mesh}" scale="0.001 0.001 0.001"/></geometry>'
    return (
        f'<link name="{name}"><inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/><mass '
        f'value="{mass}"/>'
        f'<inertia ixx="{inertia[0]}" ixy="0" ixz="0" iyy="{inertia[1]}" iyz="0" '
        f'izz="{inertia[2]}"/></inertial>'
        f"<visual>{geom}</visual><collision>{geom}</collision></link>\n"
    )


def _joint(
    name: str,
    kind: str,
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    axis: str,
    lower: float,
    upper: float,
    effort: float,
    velocity: float,
) -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="0 0 0"/><axis xyz="{axis}"/>'
        f'<limit lower="{lower}" upper="{upper}" effort="{effort}" '
        f'velocity="{velocity}"/></joint>\n'
    )


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
    urdf = "".join(
        [
            '<?xml version="1.0"?>\n<robot name="stl_scara">\n',
            _link("base", "base.stl", 10.0, (0, 0, 0.076), (0.04, 0.04, 0.04)),
            _joint(
                JOINTS["shoulder"],
                "revolute",
                "base",
                "arm1",
                (0, 0, SHOULDER_Z_M),
                "0 0 1",
                -lim[0],
                lim[0],
                60,
                3,
            ),
            _link("arm1", "arm1.stl", 1.5, (0.2335, 0, 0.025), (0.0011, 0.037, 0.0376)),
            _joint(
                JOINTS["elbow"],
                "revolute",
                "arm1",
                "arm2",
                (LINK1_M, 0, ELBOW_DZ_M),
                "0 0 1",
                -lim[1],
                lim[1],
                60,
                3,
            ),
            _link("arm2", "arm2.stl", 1.0, (0.2, 0, 0.02), (0.0007, 0.02, 0.0205)),
            _joint(
                JOINTS["z"],
                "prismatic",
                "arm2",
                "quill",
                (LINK2_M, 0, 0),
                "0 0 -1",
                0,
                0.2,
                60,
                0.5,
            ),
            _link("quill", "quill.stl", 0.37, (0, 0, 0.215), (0.0028, 0.0028, 0.00003)),
            _joint(
                JOINTS["wrist"],
                "revolute",
                "quill",
                "tool0",
                (0, 0, PAD_ABOVE_Z_JOINT_M),
                "0 0 1",
                -math.pi,
                math.pi,
                60,
                3,
            ),
            _link("tool0", "cup.stl", 0.05, (0, 0, 0), (7.4e-6, 7.4e-6, 1e-5)),
            "</robot>\n",
        ]
    )
    (folder / "stl_scara.urdf").write_text(urdf)
    joints = "\n".join(f'{role} = "{name}"' for role, name in JOINTS.items())
    profile = folder / "stl_scara.toml"
    profile.write_text(
        f'name = "stl_scara"\nurdf = "stl_scara.urdf"\npad_link = "tool0"\n'
        f'suction_signal = "{suction_signal}"\npad_length_m = {PAD_LENGTH_M}\n\n'
        f"[joints]\n{joints}\n"
    )
    return profile
