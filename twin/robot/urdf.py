"""URDF text from a profile (primitives with real masses and inertias), and profiles from a
user's URDF (links may use STL meshes)."""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from twin.model.errors import ConfigError
from twin.model.profiles import RobotProfile

ALUMINIUM_KG_M3 = 2700.0
LINK_WIDTH_M = 0.08
QUILL_RADIUS_M = 0.012
# Link 2's arm rides on a hub above the elbow axis, high enough that the pad and a held 5 cm box
# pass under it at the top of the Z stroke (otherwise a carried box would sit inside the arm).
LINK2_RISE_M = 0.075
QUILL_LENGTH_M = 0.30
PAD_RADIUS_M = 0.02
PAD_MASS_KG = 0.05
BASE_RADIUS_M = 0.09


def _box_inertia(m: float, sx: float, sy: float, sz: float) -> tuple[float, float, float]:
    return (
        m * (sy * sy + sz * sz) / 12.0,
        m * (sx * sx + sz * sz) / 12.0,
        m * (sx * sx + sy * sy) / 12.0,
    )


def _cyl_inertia(m: float, r: float, h: float) -> tuple[float, float, float]:
    side = m * (3.0 * r * r + h * h) / 12.0
    return (side, side, m * r * r / 2.0)


def _f(v: float) -> str:
    return repr(float(v))


def _link(
    name: str,
    geom: str,
    origin_xyz: tuple[float, float, float],
    mass: float,
    inertia: tuple[float, float, float],
    inertial_xyz: tuple[float, float, float],
    rgba: str,
    extra_parts: tuple[tuple[str, tuple[float, float, float]], ...] = (),
    inertial_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> str:
    """A link: one or more (geometry, origin) parts drawn and colliding alike; principal moments
    of inertia (ixx, iyy, izz) about the inertial origin, whose axes are turned by inertial_rpy."""
    ix, iy, iz = (_f(v) for v in inertial_xyz)
    rr, rp, ry = (_f(v) for v in inertial_rpy)
    xx, yy, zz = (_f(v) for v in inertia)
    shapes = []
    for part_geom, (ox, oy, oz) in ((geom, origin_xyz), *extra_parts):
        o = f'<origin xyz="{_f(ox)} {_f(oy)} {_f(oz)}"/>'
        shapes.append(
            f'    <visual>{o}<geometry>{part_geom}</geometry><material name="{name}_m">'
            f'<color rgba="{rgba}"/></material></visual>\n'
            f"    <collision>{o}<geometry>{part_geom}</geometry></collision>\n"
        )
    return f"""  <link name="{name}">
    <inertial><origin xyz="{ix} {iy} {iz}" rpy="{rr} {rp} {ry}"/><mass value="{_f(mass)}"/>
      <inertia ixx="{xx}" ixy="0" ixz="0" iyy="{yy}" iyz="0" izz="{zz}"/></inertial>
{"".join(shapes)}  </link>
"""


def _combined(
    parts: list[tuple[float, tuple[float, float, float], tuple[float, float, float]]],
) -> tuple[
    float, tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]
]:
    """Mass, centre of mass, principal moments and the rpy of the principal axes of rigid parts
    given as (mass, centre, principal moments about that centre, axes along the link frame's). Plain
    float arithmetic and Jacobi rotations, no BLAS or LAPACK (whose kernel numpy picks by CPU), and
    moments and angles rounded to URDF_DIGITS: every x86-64 CPU writes the same URDF."""
    mass = sum(m for m, _c, _i in parts)
    com = [sum(m * c[k] for m, c, _i in parts) / mass for k in range(3)]
    tensor = [[0.0] * 3 for _ in range(3)]
    for m, c, moments in parts:
        d = [c[k] - com[k] for k in range(3)]
        d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        for i in range(3):
            tensor[i][i] += moments[i] + m * d2
            for j in range(3):
                tensor[i][j] -= m * d[i] * d[j]
    values, axes = _jacobi_eigen(tensor)
    # keep each axis near the link's own
    order = [max(range(3), key=lambda j, k=k: abs(axes[k][j])) for k in range(3)]
    values = [values[j] for j in order]
    axes = [[axes[i][j] for j in order] for i in range(3)]
    for j in range(3):
        if axes[j][j] < 0:
            for i in range(3):
                axes[i][j] = -axes[i][j]
    roll = math.atan2(axes[2][1], axes[2][2])
    pitch = math.atan2(-axes[2][0], math.hypot(axes[0][0], axes[1][0]))
    yaw = math.atan2(axes[1][0], axes[0][0])
    return (
        mass,
        (com[0], com[1], com[2]),
        tuple(_rounded(v) for v in values),  # type: ignore[return-value]
        tuple(_rounded(a) for a in (roll, pitch, yaw)),
    )  # type: ignore[return-value]


# significant digits of computed inertias and inertial angles: far above the last bits a libm may
# change
URDF_DIGITS = 12


def _rounded(x: float) -> float:
    """x to URDF_DIGITS significant digits (Python's decimal rounding: the same on every platform);
    below 1e-15 (a rounding residue of an exact zero) it is 0."""
    return 0.0 if abs(x) < 1e-15 else float(f"{x:.{URDF_DIGITS}g}")


def _jacobi_eigen(a: list[list[float]]) -> tuple[list[float], list[list[float]]]:
    """Eigenvalues and eigenvectors (columns) of a symmetric 3x3 matrix by cyclic Jacobi rotations,
    in plain float arithmetic (the same bits on every CPU)."""
    a = [row[:] for row in a]
    v = [[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)]
    for _sweep in range(50):
        if a[0][1] == 0.0 and a[0][2] == 0.0 and a[1][2] == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if a[p][q] == 0.0:
                continue
            theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q])
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):  # columns p, q of a·J
                akp, akq = a[k][p], a[k][q]
                a[k][p], a[k][q] = c * akp - s * akq, s * akp + c * akq
            for k in range(3):  # rows p, q of Jᵀ·(a·J)
                apk, aqk = a[p][k], a[q][k]
                a[p][k], a[q][k] = c * apk - s * aqk, s * apk + c * aqk
            a[p][q] = a[q][p] = 0.0
            for k in range(3):
                vkp, vkq = v[k][p], v[k][q]
                v[k][p], v[k][q] = c * vkp - s * vkq, s * vkp + c * vkq
    return [a[0][0], a[1][1], a[2][2]], v


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
    yaw_rad: float = 0.0,
) -> str:
    """A joint; a "continuous" one (cyclic) has no position limits, only effort and velocity."""
    x, y, z = (_f(v) for v in xyz)
    rpy = f' rpy="0 0 {_f(yaw_rad)}"' if yaw_rad else ""
    bounds = "" if kind == "continuous" else f'lower="{_f(lower)}" upper="{_f(upper)}" '
    return f"""  <joint name="{name}" type="{kind}">
    <parent link="{parent}"/><child link="{child}"/>\
<origin xyz="{x} {y} {z}"{rpy}/><axis xyz="{axis}"/>
    <limit {bounds}effort="{_f(effort)}" velocity="{_f(velocity)}"/>
  </joint>
"""


def _axis(sign: int) -> str:
    """A vertical joint axis: +z for sign +1, -z for -1."""
    return "0 0 1" if sign > 0 else "0 0 -1"


def pad_root_height_m(profile: RobotProfile) -> float:
    return profile.tip_z0_m + profile.pad_length_m


def urdf_from_profile(profile: RobotProfile) -> str:
    """A URDF of the profile's SCARA built from boxes and cylinders (aluminium links), in the
    profile's joint conventions: link 1 along shoulder_zero_rad at zero, each axis turned by its
    sign, cyclic revolute joints continuous."""
    parts = [
        f'<?xml version="1.0"?>\n<robot name="{profile.name}">\n',
        *_shoulder_parts(profile),
        *_elbow_parts(profile),
        *_quill_and_pad_parts(profile),
        "</robot>\n",
    ]
    return "".join(parts)


def _revolute(p: RobotProfile) -> dict:
    """What the three revolute joints share: their kind, effort and velocity."""
    return {
        "kind": "continuous" if p.revolute_cyclic else "revolute",
        "effort": p.revolute_max_torque_nm,
        "velocity": p.revolute_max_velocity_rad_s,
    }


def _shoulder_parts(p: RobotProfile) -> list[str]:
    """The base, the shoulder joint and link 1 (a hollow aluminium box, 25 % fill)."""
    h1 = p.elbow_height_m - p.shoulder_height_m
    l1, m_base = p.link1_m, 8.0
    m1 = ALUMINIUM_KG_M3 * (l1 + LINK_WIDTH_M) * LINK_WIDTH_M * h1 * 0.25
    base_centre = (0.0, 0.0, p.shoulder_height_m / 2)
    lower, upper = p.joint_limits()[0]
    return [
        _link(
            name="MTB_base",
            geom=f'<cylinder radius="{_f(BASE_RADIUS_M)}" length="{_f(p.shoulder_height_m)}"/>',
            origin_xyz=base_centre,
            mass=m_base,
            inertia=_cyl_inertia(m_base, BASE_RADIUS_M, p.shoulder_height_m),
            inertial_xyz=base_centre,
            rgba="0.3 0.3 0.35 1",
        ),
        _joint(
            name=p.joint_names[0],
            parent="MTB_base",
            child="MTB_link1",
            xyz=(0.0, 0.0, p.shoulder_height_m),
            axis=_axis(p.axis_signs[0]),
            lower=lower,
            upper=upper,
            yaw_rad=p.shoulder_zero_rad,
            **_revolute(p),
        ),
        _link(
            name="MTB_link1",
            geom=f'<box size="{_f(l1 + LINK_WIDTH_M)} {_f(LINK_WIDTH_M)} {_f(h1)}"/>',
            origin_xyz=(l1 / 2, 0.0, h1 / 2),
            mass=m1,
            inertia=_box_inertia(m1, l1 + LINK_WIDTH_M, LINK_WIDTH_M, h1),
            inertial_xyz=(l1 / 2, 0.0, h1 / 2),
            rgba="0.9 0.5 0.1 1",
        ),
    ]


def _elbow_parts(p: RobotProfile) -> list[str]:
    """The elbow joint and link 2: the arm (a hollow box) on a hub that rises to it, one inertia."""
    h1, h2 = p.elbow_height_m - p.shoulder_height_m, 0.04
    l2, hub_r = p.link2_m, LINK_WIDTH_M / 2
    m2 = ALUMINIUM_KG_M3 * (l2 + LINK_WIDTH_M) * LINK_WIDTH_M * h2 * 0.25
    m_hub = ALUMINIUM_KG_M3 * math.pi * hub_r**2 * LINK2_RISE_M * 0.25
    arm2_centre = (l2 / 2, 0.0, LINK2_RISE_M + h2 / 2)
    hub_centre = (0.0, 0.0, LINK2_RISE_M / 2)
    link2_mass, link2_com, link2_inertia, link2_rpy = _combined(
        [
            (m2, arm2_centre, _box_inertia(m2, l2 + LINK_WIDTH_M, LINK_WIDTH_M, h2)),
            (m_hub, hub_centre, _cyl_inertia(m_hub, hub_r, LINK2_RISE_M)),
        ]
    )
    lower, upper = p.joint_limits()[1]
    return [
        _joint(
            name=p.joint_names[1],
            parent="MTB_link1",
            child="MTB_link2",
            xyz=(p.link1_m, 0.0, h1),
            axis=_axis(p.axis_signs[1]),
            lower=lower,
            upper=upper,
            **_revolute(p),
        ),
        _link(
            name="MTB_link2",
            geom=f'<box size="{_f(l2 + LINK_WIDTH_M)} {_f(LINK_WIDTH_M)} {_f(h2)}"/>',
            origin_xyz=arm2_centre,
            mass=link2_mass,
            inertia=link2_inertia,
            inertial_xyz=link2_com,
            rgba="0.9 0.6 0.2 1",
            extra_parts=(
                (f'<cylinder radius="{_f(hub_r)}" length="{_f(LINK2_RISE_M)}"/>', hub_centre),
            ),
            inertial_rpy=link2_rpy,
        ),
    ]


def _quill_and_pad_parts(p: RobotProfile) -> list[str]:
    """The Z joint and its quill (link 3), the wrist joint and the suction pad."""
    m3 = ALUMINIUM_KG_M3 * math.pi * QUILL_RADIUS_M**2 * QUILL_LENGTH_M
    pad_offset = pad_root_height_m(p) - p.elbow_height_m  # axis4 above the Z joint's frame
    pad_h = p.pad_length_m
    pad_inertia = _cyl_inertia(PAD_MASS_KG, PAD_RADIUS_M, pad_h)
    limits = p.joint_limits()
    quill_centre = (0.0, 0.0, pad_offset + QUILL_LENGTH_M / 2)
    return [
        _joint(
            name=p.joint_names[2],
            kind="prismatic",
            parent="MTB_link2",
            child="MTB_link3",
            xyz=(p.link2_m, 0.0, 0.0),
            axis=_axis(-p.axis_signs[2]),
            lower=limits[2][0],
            upper=limits[2][1],
            effort=p.prismatic_max_force_n,
            velocity=p.prismatic_max_velocity_m_s,
        ),
        _link(
            name="MTB_link3",
            geom=f'<cylinder radius="{_f(QUILL_RADIUS_M)}" length="{_f(QUILL_LENGTH_M)}"/>',
            origin_xyz=quill_centre,
            mass=m3,
            inertia=_cyl_inertia(m3, QUILL_RADIUS_M, QUILL_LENGTH_M),
            inertial_xyz=quill_centre,
            rgba="0.7 0.7 0.75 1",
        ),
        _joint(
            name=p.joint_names[3],
            parent="MTB_link3",
            child="suctionPad",
            xyz=(0.0, 0.0, pad_offset),
            axis=_axis(p.axis_signs[3]),
            lower=limits[3][0],
            upper=limits[3][1],
            **_revolute(p),
        ),
        # The pad's inertial frame sits at its root so a held object's constraint frame is simple.
        _link(
            name="suctionPad",
            geom=f'<cylinder radius="{_f(PAD_RADIUS_M)}" length="{_f(pad_h)}"/>',
            origin_xyz=(0.0, 0.0, -pad_h / 2),
            mass=PAD_MASS_KG,
            inertia=(
                pad_inertia[0] + PAD_MASS_KG * (pad_h / 2) ** 2,
                pad_inertia[1] + PAD_MASS_KG * (pad_h / 2) ** 2,
                pad_inertia[2],
            ),
            inertial_xyz=(0.0, 0.0, 0.0),
            rgba="0.1 0.1 0.1 1",
        ),
    ]


def urdf_text(profile: RobotProfile) -> str:
    """The URDF the world loads for this profile: the user's file, or one built from primitives."""
    if profile.urdf_path:
        try:
            return Path(profile.urdf_path).read_text()
        except OSError as err:
            raise ConfigError(f"cannot read URDF {profile.urdf_path!r}: {err}") from err
    return urdf_from_profile(profile)


def mesh_paths(profile: RobotProfile) -> list[Path]:
    """The mesh files a user URDF references (resolved next to the URDF), sorted; [] for
    built-ins."""
    if not profile.urdf_path:
        return []
    base = Path(profile.urdf_path).parent
    root = ET.fromstring(urdf_text(profile))
    names = {m.get("filename", "") for m in root.iter("mesh")}
    return sorted((base / n.removeprefix("file://")).resolve() for n in names if n)


def vector3(
    elem: ET.Element | None,
    attr: str = "xyz",
    default: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[float, float, float]:
    """A URDF element's three-number attribute (xyz, rpy); the default when the element or attribute
    is absent; ConfigError when it is not three numbers."""
    if elem is None or elem.get(attr) is None:
        return default
    try:
        vals = [float(v) for v in elem.get(attr, "").split()]
    except ValueError:
        vals = []
    if len(vals) != 3:
        raise ConfigError(f"URDF {attr}={elem.get(attr)!r}: expected three numbers")
    return (vals[0], vals[1], vals[2])


MOVING_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint as the transforms need it: the one reading of a joint element, which the MCAP
    transforms (one value at a time) and the Rerun drawing (many at once) both turn into poses.

    The child frame sits at `xyz`, rotated by `rpy`, from the parent's; a revolute or continuous
    joint then turns it about `axis` (a unit vector in the joint frame), a prismatic one slides
    it."""

    name: str
    kind: str  # revolute | continuous | prismatic | fixed | ...
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]  # unit length; URDF's default (1, 0, 0) when absent

    @property
    def moving(self) -> bool:
        return self.kind in MOVING_TYPES


def parse_urdf(urdf: str) -> ET.Element:
    """A URDF text's root element; ConfigError when it does not parse."""
    try:
        return ET.fromstring(urdf)
    except ET.ParseError as err:
        raise ConfigError(f"robot URDF does not parse: {err}") from err


def urdf_joints(urdf: str | ET.Element) -> list[UrdfJoint]:
    """Every joint of a URDF (its text, or parse_urdf's root of it), in document order; ConfigError
    when it does not parse or a joint lacks its parent or child, or a moving joint has no
    direction."""
    root = parse_urdf(urdf) if isinstance(urdf, str) else urdf
    joints = []
    for elem in root.iter("joint"):
        name = elem.get("name", "")
        parent, child = elem.find("parent"), elem.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            raise ConfigError(f"URDF joint {name!r} needs a parent and a child link")
        origin = elem.find("origin")
        axis = vector3(elem.find("axis"), "xyz", (1.0, 0.0, 0.0))
        norm = math.sqrt(sum(a * a for a in axis))
        kind = elem.get("type", "fixed")
        if kind in MOVING_TYPES and not norm > 0.0:
            raise ConfigError(
                f"URDF joint {name!r} has a zero axis; expected a direction like '0 0 1'"
            )
        joints.append(
            UrdfJoint(
                name=name,
                kind=kind,
                parent=parent.get("link"),
                child=child.get("link"),
                xyz=vector3(origin, "xyz"),
                rpy=vector3(origin, "rpy"),
                axis=tuple(a / (norm or 1.0) for a in axis),
            )
        )
    return joints


def profile_from_urdf(
    urdf_path: Path, *, name: str, joint_names: tuple[str, ...], pad_link: str, pad_length_m: float
) -> RobotProfile:
    """Derive a SCARA profile from a user URDF: link lengths and heights from joint origins
    (translations only, vertical joint axes), limits from the joints' <limit> tags."""
    if not urdf_path.is_file():
        raise ConfigError(f"URDF {str(urdf_path)!r} does not exist")
    try:
        root = ET.parse(urdf_path).getroot()
    except ET.ParseError as err:
        raise ConfigError(f"URDF {str(urdf_path)!r} is not valid XML: {err}") from err
    joints = {j.get("name"): j for j in root.findall("joint")}
    by_child = {
        j.find("child").get("link"): j for j in root.findall("joint") if j.find("child") is not None
    }
    world_origin = functools.partial(_world_origin, by_child)
    missing = [n for n in joint_names if n not in joints]
    if missing:
        raise ConfigError(
            f"URDF {str(urdf_path)!r} has no joint named {missing[0]!r}; it has {sorted(joints)}"
        )
    if pad_link not in {lk.get("name") for lk in root.findall("link")}:
        raise ConfigError(f"URDF {str(urdf_path)!r} has no link named {pad_link!r}")
    shoulder, elbow, zj, _wrist = (joints[n] for n in joint_names)
    if vector3(zj.find("axis")) != (0.0, 0.0, -1.0):
        raise ConfigError(
            f"URDF joint {zj.get('name')!r}: expected axis '0 0 -1' (positive lowers the pad)"
        )
    s_world = world_origin(shoulder.find("child").get("link"))
    e_world = world_origin(elbow.find("child").get("link"))
    pad_world = world_origin(pad_link)

    s_lim, e_lim, z_lim, w_lim = (_limit(j) for j in (shoulder, elbow, zj, _wrist))
    return RobotProfile(
        name=name,
        link1_m=math.hypot(e_world[0] - s_world[0], e_world[1] - s_world[1]),
        link2_m=math.hypot(pad_world[0] - e_world[0], pad_world[1] - e_world[1]),
        joint_names=tuple(joint_names),  # type: ignore[arg-type]
        shoulder_height_m=s_world[2],
        elbow_height_m=e_world[2],
        tip_z0_m=pad_world[2] - pad_length_m,
        z_stroke_m=z_lim[1],
        shoulder_limit_rad=min(abs(s_lim[0]), abs(s_lim[1])),
        elbow_limit_rad=min(abs(e_lim[0]), abs(e_lim[1])),
        wrist_limit_rad=min(abs(w_lim[0]), abs(w_lim[1])),
        revolute_max_velocity_rad_s=s_lim[3],
        prismatic_max_velocity_m_s=z_lim[3],
        revolute_max_torque_nm=s_lim[2],
        prismatic_max_force_n=z_lim[2],
        pad_length_m=pad_length_m,
        urdf_path=str(urdf_path),
        pad_link=pad_link,
        description=f"user URDF {urdf_path.name}",
    )


def _world_origin(by_child: dict[str, ET.Element], link: str) -> tuple[float, float, float]:
    """A link's origin in the world: its joints' translations summed up to the root (joint origins
    must not be rotated)."""
    x = y = z = 0.0
    while link in by_child:
        j = by_child[link]
        origin = j.find("origin")
        if origin is not None and any(abs(v) > 1e-12 for v in vector3(origin, "rpy")):
            raise ConfigError(
                f"URDF joint {j.get('name')!r} has a rotated origin; expected rpy 0 0 0"
            )
        dx, dy, dz = vector3(origin)
        x, y, z = x + dx, y + dy, z + dz
        link = j.find("parent").get("link")
    return (x, y, z)


def _limit(j: ET.Element) -> tuple[float, float, float, float]:
    """A joint's (lower, upper, effort, velocity) from its <limit>."""
    lim = j.find("limit")
    if lim is None:
        raise ConfigError(f"URDF joint {j.get('name')!r} has no <limit>")
    try:
        return tuple(
            float(lim.get(k, d))
            for k, d in (("lower", 0), ("upper", 0), ("effort", 50), ("velocity", 1))
        )
    except ValueError as err:
        raise ConfigError(
            f"URDF joint {j.get('name')!r} <limit> has a value that is not a number: {err}"
        ) from err
