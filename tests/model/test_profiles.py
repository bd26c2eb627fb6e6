"""Robot profiles: every variant's joint names resolve; each built-in URDF loads with its real
dynamics."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pytest

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, TwinError, UnknownName
from twin.model.profiles import JOINT_ALIASES, PROFILES, ROLES, RobotProfile
from twin.robot.profile_files import get_profile
from twin.robot.urdf import urdf_from_profile
from twin.sim.world import World, pb

SHOULDER_NAMES = ("MTB_axis1", "joint1", "Revolute_joint", "AB")
VARIANT_NAMES = {  # role -> the names the four reports and the MTB scene use
    "shoulder": SHOULDER_NAMES,
    "elbow": ("MTB_axis2", "joint2", "Revolute_joint1", "BC"),
    "z": ("MTB_axis3", "joint3", "Prismatic_joint", "Z"),
    "wrist": ("MTB_axis4", "joint4", "Revolute_joint0", "CD"),
}


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
@pytest.mark.parametrize("role", ROLES)
def test_every_variant_name_resolves_to_its_role_with_or_without_slash(profile_name, role):
    profile = PROFILES[profile_name]
    for name in VARIANT_NAMES[role] + JOINT_ALIASES[role]:
        assert profile.joint_index(name) == ROLES.index(role), name
        assert profile.joint_index("/" + name) == ROLES.index(role), "/" + name


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
def test_each_profile_names_its_own_joints(profile_name):
    profile = PROFILES[profile_name]
    assert [profile.joint_index(n) for n in profile.joint_names] == [0, 1, 2, 3]


@pytest.mark.parametrize("bad", ["MTB_axis9", "Revolute_joint2", "shoulderr", "", "//"])
def test_unknown_joint_names_raise_unknown_name_naming_the_value(bad):
    with pytest.raises(UnknownName) as err:
        PROFILES["seed001"].joint_index(bad)
    assert repr(bad) in str(err.value)
    assert "Revolute_joint" in str(err.value)  # says what was expected
    assert isinstance(err.value, TwinError) and err.value.exit_code == 2


def test_unknown_robot_raises_config_error_listing_the_profiles():
    with pytest.raises(ConfigError) as err:
        get_profile("scara9000")
    assert "'scara9000'" in str(err.value)
    for name in PROFILES:
        assert name in str(err.value)


def test_missing_profile_file_raises_naming_it(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="nope.toml"):
        get_profile(str(path))


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
def test_profile_round_trips_through_a_dict(profile_name):
    profile = PROFILES[profile_name]
    assert RobotProfile.from_dict(profile.to_dict()) == profile


def test_malformed_profile_dict_raises_config_error():
    with pytest.raises(ConfigError, match="malformed robot profile"):
        RobotProfile.from_dict({"name": "x"})


def _urdf_links(text: str) -> dict[str, dict]:
    """Mass, diagonal inertia and inertial origin of every link, read straight from the URDF
    text."""
    out = {}
    for link in ET.fromstring(text).iter("link"):
        inertial = link.find("inertial")
        inertia = inertial.find("inertia")
        out[link.get("name")] = {
            "mass": float(inertial.find("mass").get("value")),
            "inertia": tuple(float(inertia.get(a)) for a in ("ixx", "iyy", "izz")),
            "origin": tuple(float(v) for v in inertial.find("origin").get("xyz").split()),
        }
    return out


def _loaded_links(world: World) -> dict[str, tuple]:
    c = world.client
    out = {}
    for j in range(pb.getNumJoints(world.robot, physicsClientId=c)):
        link = pb.getJointInfo(world.robot, j, physicsClientId=c)[12].decode()
        out[link] = pb.getDynamicsInfo(world.robot, j, physicsClientId=c)
    return out


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
def test_urdf_loads_with_its_real_masses_and_inertias(profile_name):
    profile = PROFILES[profile_name]
    world = World(TwinConfig(profile=profile))
    try:
        assert world.urdf_text == urdf_from_profile(profile)
        expected = _urdf_links(world.urdf_text)
        loaded = _loaded_links(world)
        # the fixed base is not simulated
        assert sorted(loaded) == sorted(n for n in expected if n != "MTB_base")
        for link, info in loaded.items():
            mass, inertia, origin = info[0], info[2], info[3]
            assert mass == pytest.approx(expected[link]["mass"], rel=1e-12), link
            assert mass > 0.0
            assert inertia == pytest.approx(expected[link]["inertia"], rel=1e-9), link
            assert origin == pytest.approx(expected[link]["origin"], abs=1e-9), link
    finally:
        world.close()


def test_without_the_inertia_flag_pybullet_would_invent_inertias(tmp_path):
    """Guards the test above: PyBullet's default load replaces the URDF's inertias, so it can
    fail."""
    profile = PROFILES["mtb"]
    path = tmp_path / "mtb.urdf"
    path.write_text(urdf_from_profile(profile))
    expected = _urdf_links(path.read_text())
    client = pb.connect(pb.DIRECT)
    try:
        robot = pb.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
        differ = []
        for j in range(pb.getNumJoints(robot, physicsClientId=client)):
            link = pb.getJointInfo(robot, j, physicsClientId=client)[12].decode()
            inertia = pb.getDynamicsInfo(robot, j, physicsClientId=client)[2]
            if inertia != pytest.approx(expected[link]["inertia"], rel=1e-6):
                differ.append(link)
        assert differ
    finally:
        pb.disconnect(client)


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
def test_urdf_joints_carry_the_profile_names_limits_and_link_lengths(profile_name):
    profile = PROFILES[profile_name]
    root = ET.fromstring(urdf_from_profile(profile))
    joints = root.findall("joint")
    assert tuple(j.get("name") for j in joints) == profile.joint_names
    revolute = "continuous" if profile.revolute_cyclic else "revolute"  # CoppeliaSim's cyclic joint
    assert [j.get("type") for j in joints] == [revolute, revolute, "prismatic", revolute]
    for joint, (lo, hi) in zip(joints, profile.joint_limits(), strict=True):
        limit = joint.find("limit")
        if joint.get("type") == "continuous":
            assert limit.get("lower") is None and limit.get("upper") is None
        else:
            assert (float(limit.get("lower")), float(limit.get("upper"))) == (lo, hi)
    axes = [joint.find("axis").get("xyz") for joint in joints]
    signs = profile.axis_signs
    assert axes == [
        f"0 0 {'1' if signs[0] > 0 else '-1'}",
        f"0 0 {'1' if signs[1] > 0 else '-1'}",
        f"0 0 {'-1' if signs[2] > 0 else '1'}",
        f"0 0 {'1' if signs[3] > 0 else '-1'}",
    ]
    elbow_xyz = [float(v) for v in joints[1].find("origin").get("xyz").split()]
    z_xyz = [float(v) for v in joints[2].find("origin").get("xyz").split()]
    assert math.hypot(*elbow_xyz[:2]) == profile.link1_m
    assert math.hypot(*z_xyz[:2]) == profile.link2_m


def test_the_seed_profiles_carry_the_reports_link_lengths():
    lengths = {name: (p.link1_m, p.link2_m) for name, p in PROFILES.items()}
    assert lengths == {
        "mtb": (0.467, 0.4005),
        "seed000": (0.8, 0.8),
        "seed001": (0.467, 0.401),
        "seed002": (0.5, 0.5),
        "seed003": (0.468, 0.4),
    }
    assert PROFILES["seed003"].suction_signals[0] == "suctionPad"


@pytest.mark.parametrize("profile_name", sorted(PROFILES))
def test_the_simulated_pad_sits_where_the_kinematics_put_it(profile_name):
    """The URDF built from a profile and the profile's fk agree: the pad link's origin (its root)
    is pad_length above the fk tip, and its yaw is the fk heading."""
    from twin.robot import kinematics
    from twin.sim.twin import Twin

    twin = Twin(TwinConfig(profile=PROFILES[profile_name]))
    try:
        w = twin._world  # the engine, looked at directly (white-box)
        z_lo, z_hi = twin.profile.joint_limits()[2]
        for q in [
            (0.3, -1.1, z_lo + 0.25 * (z_hi - z_lo), 0.7),
            (-2.5, 2.0, z_hi, -3.0),
            (1.9, 0.4, z_lo, 2.2),
        ]:
            for joint, value in enumerate(q):
                twin.set_joint_position(joint, value)
            fk = kinematics.fk(twin.profile, q)
            pos, orn = pb.getLinkState(
                w.robot, w.pad_link, computeForwardKinematics=1, physicsClientId=w.client
            )[4:6]
            assert pos == pytest.approx(
                (fk.x_m, fk.y_m, fk.z_m + twin.profile.pad_length_m), abs=1e-6
            )
            yaw = pb.getEulerFromQuaternion(orn)[2]
            assert abs(kinematics.wrap_rad(yaw - fk.heading_rad)) < 1e-6
            assert twin.pad_position() == pytest.approx((fk.x_m, fk.y_m, fk.z_m), abs=1e-12)
    finally:
        twin.close()


def test_a_profiles_own_joint_names_win_over_other_variants_aliases():
    from dataclasses import replace

    # a user robot whose Z joint is called joint4 and its wrist joint3 (seed000's names for wrist
    # and Z)
    swapped = replace(PROFILES["mtb"], name="user", joint_names=("s", "e", "joint4", "joint3"))
    assert swapped.joint_index("joint3") == 3 and swapped.joint_index("/joint4") == 2
    assert swapped.joint_index("MTB_axis1") == 0  # other variants' aliases still resolve
