"""Robot profiles: the MTB SCARA and the students' variants, selectable by name.

A profile is data: geometry, limits, joint names and suction signals. It round-trips through a
plain dict so a recording can carry it and replay can rebuild the robot from the file alone.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from twin.model.errors import ConfigError, UnknownName

ROLES = ("shoulder", "elbow", "z", "wrist")

# Every joint name used by a known variant, by role: a script for any seed's scene finds its joint.
JOINT_ALIASES: dict[str, tuple[str, ...]] = {
    "shoulder": ("MTB_axis1", "joint1", "Revolute_joint", "AB", "axis1", "shoulder"),
    "elbow": ("MTB_axis2", "joint2", "Revolute_joint1", "BC", "axis2", "elbow"),
    "z": ("MTB_axis3", "joint3", "Prismatic_joint", "Z", "axis3", "z"),
    "wrist": ("MTB_axis4", "joint4", "Revolute_joint0", "CD", "axis4", "wrist"),
}
PAD_ALIASES = ("suctionPad", "suctionPad_sensor", "pad", "MTB_suctionPad")
ROBOT_ALIASES = ("MTB_Robot", "MTB_base", "robot", "base")
DEFAULT_SUCTION_SIGNAL = "pad_switch"
CYCLIC_RANGE_RAD = 2.0 * math.pi
# CoppeliaSim 4.1's defaults for a new joint's position control: 360 deg/s for a revolute joint (the
# seeds' own joints; their programs' sleeps assume it), 10 m/s for a prismatic one. The twin keeps
# 0.5 m/s for Z: every seed's Z move (at most 0.12 m) still ends within its program's shortest sleep
# (0.5 s). Motor torques are sized so each arm settles (1 mrad) within its program's 0.5 s sleeps
# (the settle times measured are in CHANGES.md).
COPPELIASIM_REVOLUTE_RAD_S = 2.0 * math.pi


@dataclass(frozen=True)
class RobotProfile:
    """Geometry and limits of one SCARA variant (metres, radians, kilograms, newtons)."""

    name: str
    link1_m: float
    link2_m: float
    joint_names: tuple[str, str, str, str]  # shoulder, elbow, z, wrist as the variant names them
    suction_signals: tuple[str, ...] = (DEFAULT_SUCTION_SIGNAL,)
    shoulder_height_m: float = 0.152
    elbow_height_m: float = 0.202
    tip_z0_m: float = 0.255  # pad tip height with the Z joint at 0
    z_stroke_m: float = 0.2
    shoulder_limit_rad: float = math.radians(160.0)
    elbow_limit_rad: float = math.radians(150.0)
    wrist_limit_rad: float = math.pi
    revolute_max_velocity_rad_s: float = 3.0
    prismatic_max_velocity_m_s: float = 0.5
    revolute_max_torque_nm: float = 60.0
    prismatic_max_force_n: float = 60.0
    pad_length_m: float = 0.012  # pad root to tip
    urdf_path: str = ""  # a user's URDF (with meshes); empty: built from primitives
    pad_link: str = ""  # the user URDF's link whose origin is the pad root
    description: str = ""
    extra: dict = field(default_factory=dict, compare=False)
    # The scene's own joint conventions (docs/seed-conventions.md derives each seed's from its
    # report):
    shoulder_zero_rad: float = 0.0  # direction of link 1 at shoulder 0, counter-clockwise from +x
    # +1: revolute turns counter-clockwise seen from
    axis_signs: tuple[int, int, int, int] = (1, 1, 1, 1)
    # above (axis +z); Z lowers the pad with positive values (axis -z)
    # CoppeliaSim's default revolute joint: no limits, turns the short way
    revolute_cyclic: bool = False
    z_lower_m: float = 0.0  # the Z joint's lower limit; its upper limit is z_lower_m + z_stroke_m
    # the Z value that puts the pad on a 50 mm box (None: the stroke's low end)
    z_down_m: float | None = None
    z_up_m: float | None = None  # the Z value the scene travels at (None: the stroke's high end)

    def __post_init__(self) -> None:
        """Fill in z_down_m / z_up_m from the stroke's ends (so a profile's dict always holds
        numbers)."""
        lo, hi = self.z_lower_m, self.z_lower_m + self.z_stroke_m
        lowering = self.axis_signs[2] > 0
        if self.z_down_m is None:
            object.__setattr__(self, "z_down_m", hi if lowering else lo)
        if self.z_up_m is None:
            object.__setattr__(self, "z_up_m", lo if lowering else hi)

    @property
    def reach_m(self) -> tuple[float, float]:
        """Inner and outer radius of the annulus the pad can reach within the elbow limit (a cyclic
        elbow folds fully: |l1 - l2|)."""
        l1, l2 = self.link1_m, self.link2_m
        if self.revolute_cyclic:  # the elbow folds all the way
            return abs(l1 - l2), l1 + l2
        inner = math.sqrt(
            max(0.0, l1 * l1 + l2 * l2 + 2 * l1 * l2 * math.cos(self.elbow_limit_rad))
        )
        return inner, l1 + l2

    def joint_limits(self) -> tuple[tuple[float, float], ...]:
        """(lower, upper) per joint in role order: rad, rad, m, rad. A cyclic revolute joint has no
        limit; it reports +-2 pi (one turn either way of zero), which its short-way targets never
        pass."""
        turn = CYCLIC_RANGE_RAD
        return (
            (-turn, turn)
            if self.revolute_cyclic
            else (-self.shoulder_limit_rad, self.shoulder_limit_rad),
            (-turn, turn)
            if self.revolute_cyclic
            else (-self.elbow_limit_rad, self.elbow_limit_rad),
            (self.z_lower_m, self.z_lower_m + self.z_stroke_m),
            (-turn, turn)
            if self.revolute_cyclic
            else (-self.wrist_limit_rad, self.wrist_limit_rad),
        )

    def z_down(self) -> float:
        """The Z joint value of the scene's "down": the pad on a 50 mm box standing on the floor."""
        return float(self.z_down_m)

    def z_up(self) -> float:
        """The Z joint value of the scene's "up" (the arm travels there)."""
        return float(self.z_up_m)

    def joint_index(self, name: str) -> int:
        """Resolve any variant's joint name (with or without a leading '/') to a role index."""
        bare = name.lstrip("/")
        # the profile's own names first: a user's "joint3" may be its wrist
        if bare in self.joint_names:
            return self.joint_names.index(bare)
        for index, role in enumerate(ROLES):
            if bare in JOINT_ALIASES[role]:
                return index
        known = ", ".join(self.joint_names)
        raise UnknownName(
            f"unknown joint {name!r} for robot {self.name!r}; expected one of {known}"
        )

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(data: dict) -> RobotProfile:
        try:
            data = dict(data)
            data["joint_names"] = tuple(data["joint_names"])
            data["suction_signals"] = tuple(data.get("suction_signals", (DEFAULT_SUCTION_SIGNAL,)))
            if "axis_signs" in data:
                data["axis_signs"] = tuple(int(v) for v in data["axis_signs"])
            return RobotProfile(**data)
        except (TypeError, KeyError) as err:
            raise ConfigError(f"malformed robot profile: {err}") from err


PROFILES: dict[str, RobotProfile] = {
    "mtb": RobotProfile(
        name="mtb",
        link1_m=0.467,
        link2_m=0.4005,
        joint_names=("MTB_axis1", "MTB_axis2", "MTB_axis3", "MTB_axis4"),
        suction_signals=(DEFAULT_SUCTION_SIGNAL, "suctionPad"),
        description="CoppeliaSim's MTB (Machine Type B) SCARA",
    ),
    # Reports 000-002 built their own joints: CoppeliaSim's default revolute joint (cyclic, 360
    # deg/s). Their zero directions, turning senses and Z values come from their code
    # (docs/seed-conventions.md).
    "seed000": RobotProfile(
        name="seed000",
        link1_m=0.8,
        link2_m=0.8,
        joint_names=("joint1", "joint2", "joint3", "joint4"),
        description="report 000: 0.8 m / 0.8 m links; shoulder zero along +y; Z 0.06 on the box, "
        "-0.06 up",
        shoulder_zero_rad=math.pi / 2,
        revolute_cyclic=True,
        revolute_max_velocity_rad_s=COPPELIASIM_REVOLUTE_RAD_S,
        revolute_max_torque_nm=300.0,
        tip_z0_m=0.115,
        z_lower_m=-0.116,
        z_stroke_m=0.2,
        z_down_m=0.06,
        z_up_m=-0.06,
    ),
    "seed001": RobotProfile(
        name="seed001",
        link1_m=0.467,
        link2_m=0.401,
        joint_names=("Revolute_joint", "Revolute_joint1", "Prismatic_joint", "Revolute_joint0"),
        description="report 001: MTB-like links, arrow-key control; zero along +y, clockwise; Z "
        "-0.055 down, 0 up",
        shoulder_zero_rad=math.pi / 2,
        axis_signs=(-1, -1, -1, -1),
        revolute_cyclic=True,
        revolute_max_velocity_rad_s=COPPELIASIM_REVOLUTE_RAD_S,
        revolute_max_torque_nm=150.0,
        tip_z0_m=0.11,
        z_lower_m=-0.055,
        z_stroke_m=0.055,
    ),
    "seed002": RobotProfile(
        name="seed002",
        link1_m=0.5,
        link2_m=0.5,
        joint_names=("AB", "BC", "Z", "CD"),
        description="report 002: 0.5 m / 0.5 m links; zero along +y, clockwise; Z -0.09 down, 0 up",
        shoulder_zero_rad=math.pi / 2,
        axis_signs=(-1, -1, -1, -1),
        revolute_cyclic=True,
        revolute_max_velocity_rad_s=COPPELIASIM_REVOLUTE_RAD_S,
        revolute_max_torque_nm=150.0,
        tip_z0_m=0.145,
        z_lower_m=-0.09,
        z_stroke_m=0.09,
    ),
    "seed003": RobotProfile(
        name="seed003",
        link1_m=0.468,
        link2_m=0.4,
        joint_names=("MTB_axis1", "MTB_axis2", "MTB_axis3", "MTB_axis4"),
        suction_signals=("suctionPad", DEFAULT_SUCTION_SIGNAL),
        description="report 003: MTB names and conventions (its IK is CoppeliaSim's MTB frame), "
        "suction signal 'suctionPad'",
    ),
}
