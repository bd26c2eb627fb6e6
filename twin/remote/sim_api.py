"""The `sim.*` functions and constants a remote client sees, implemented over the Scene's Twin.

Object handles are small stable integers: the robot base, its four joints (in role order), the
suction pad and the scene's objects. Any variant's names resolve (MTB_axis1, joint1,
Revolute_joint, AB, ..., with or without a leading '/', as a path '/MTB_Robot/MTB_axis2', or with
an old '#0' suffix). Poses are computed from the joint values (kinematics), in metres and radians.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from twin.model.errors import UnknownName
from twin.model.profiles import PAD_ALIASES, ROBOT_ALIASES, ROLES
from twin.model.quat import quat_mul, rotate, yaw_quat
from twin.remote.protocol import MAX_SIGNALS, Param, RequestError, Signature, brief_value, printable
from twin.remote.session import (
    SIMULATION_ADVANCING_RUNNING,
    SIMULATION_PAUSED,
    SIMULATION_STOPPED,
    Scene,
)
from twin.robot import kinematics

HANDLE_WORLD = -1
HANDLE_ROBOT = 10
HANDLE_JOINT0 = 11  # 11..14: shoulder, elbow, z, wrist
HANDLE_PAD = 15
HANDLE_OBJECT0 = 20  # 20, 21, ...: the scene's objects in scene order
# CoppeliaSim's default primitive name, for the first object
BOX_ALIASES = ("Cuboid", "box", "Box", "cuboid")
INT32 = (-(1 << 31), (1 << 31) - 1)

CONSTANTS = {
    "handle_world": HANDLE_WORLD,
    "handle_all": -2,
    "handle_self": -4,
    "handle_parent": -11,
    "handle_scene": -12,
    "handle_app": -13,
    "simulation_stopped": SIMULATION_STOPPED,
    "simulation_paused": SIMULATION_PAUSED,
    "simulation_advancing": 0x10,
    "simulation_advancing_firstafterstop": 0x10,
    "simulation_advancing_running": SIMULATION_ADVANCING_RUNNING,
    "simulation_advancing_lastbeforepause": 0x13,
    "simulation_advancing_firstafterpause": 0x14,
    "simulation_advancing_abouttostop": 0x15,
    "simulation_advancing_lastbeforestop": 0x16,
    "verbosity_none": 0,
    "verbosity_errors": 100,
    "verbosity_warnings": 200,
    "verbosity_loadinfos": 300,
    "verbosity_questions": 350,
    "verbosity_scripterrors": 400,
    "verbosity_scriptwarnings": 500,
    "verbosity_scriptinfos": 600,
    "verbosity_msgs": 600,
    "verbosity_infos": 700,
    "verbosity_debug": 800,
    "verbosity_trace": 900,
    "verbosity_default": 300,
    "object_joint_type": 1,
    "object_shape_type": 0,
    "object_dummy_type": 4,
}
VERBOSITY_NAMES = {
    0: "none",
    100: "error",
    200: "warning",
    300: "loadinfo",
    350: "question",
    400: "scripterror",
    500: "scriptwarning",
    600: "info",
    700: "info",
    800: "debug",
    900: "trace",
}

H = Param("handle", "int")
REL = Param("relativeToObjectHandle", "int", HANDLE_WORLD)


class SimApi:
    """sim.* calls that act on the scene. The server handles step, setStepping and the protocol's
    own."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.client = ""  # the calling client's label, set by the server before each call
        self.functions: dict[str, tuple[Signature, Callable]] = {}
        f = self._define
        f("getObject", (Param("path", "str"), Param("options", "map?", {})), self.get_object)
        f("getObjectHandle", (Param("name", "str"),), self.get_object_handle)
        f("getObjectAlias", (H, Param("options", "int", -1)), self.get_object_alias)
        f(
            "setJointTargetPosition",
            (H, Param("targetPosition", "float"), Param("motionParams", "list?", ())),
            self.set_joint_target_position,
        )
        f("setJointPosition", (H, Param("position", "float")), self.set_joint_position)
        f("getJointPosition", (H,), self.get_joint_position)
        f("getJointTargetPosition", (H,), self.get_joint_target_position)
        f("getJointVelocity", (H,), self.get_joint_velocity)
        for kind in ("Int32", "Integer"):  # CoppeliaSim >= 4.2 names, and the older ones
            f(
                f"set{kind}Signal",
                (Param("signalName", "name"), Param("signalValue", "int")),
                self.set_int_signal,
            )
            f(f"get{kind}Signal", (Param("signalName", "name"),), self.get_int_signal)
            f(f"clear{kind}Signal", (Param("signalName", "name"),), self.clear_int_signal)
        f("startSimulation", (), self.start_simulation)
        f("stopSimulation", (), self.stop_simulation)
        f("pauseSimulation", (), self.pause_simulation)
        f("getSimulationState", (), lambda: self.scene.state)
        f("getSimulationTime", (), lambda: self.scene.twin.t_s)
        f("getSimulationTimeStep", (), lambda: self.scene.config.dt_s)
        f("getObjectPosition", (H, REL), lambda h, rel: list(self._relative_pose(h, rel)[:3]))
        f(
            "getObjectOrientation",
            (H, REL),
            lambda h, rel: list(_euler_xyz(self._relative_pose(h, rel)[3:])),
        )
        f("getObjectQuaternion", (H, REL), lambda h, rel: list(self._relative_pose(h, rel)[3:]))
        f("getObjectPose", (H, REL), lambda h, rel: list(self._relative_pose(h, rel)))
        f("addLog", (Param("verbosityLevel", "int"), Param("logMessage", "text")), self.add_log)

    def _define(self, name: str, params: tuple[Param, ...], fn: Callable) -> None:
        self.functions[f"sim.{name}"] = (Signature(*params), fn)

    # -- names and handles -------------------------------------------------------------------
    def resolve(self, path: str) -> int:
        """The handle of an object path or name; raises UnknownName listing what exists."""
        twin = self.scene.twin
        name = path.strip().rstrip("/").split("/")[-1].split("#")[0]
        name = name.removesuffix("[0]")
        if name in ROBOT_ALIASES:
            return HANDLE_ROBOT
        if name in PAD_ALIASES:
            return HANDLE_PAD
        names = [o.name for o in twin.config.objects]
        if name in names:
            return HANDLE_OBJECT0 + names.index(name)
        if name and names and name in BOX_ALIASES:
            return HANDLE_OBJECT0
        try:
            return HANDLE_JOINT0 + twin.profile.joint_index(name)
        except UnknownName:
            known = [ROBOT_ALIASES[0], *twin.profile.joint_names, PAD_ALIASES[0], *names]
            raise UnknownName(
                f"object does not exist: {brief_value(path)}; this scene has {', '.join(known)}"
            ) from None

    def name_of(self, handle: int) -> str:
        twin = self.scene.twin
        if handle == HANDLE_ROBOT:
            return ROBOT_ALIASES[0]
        if HANDLE_JOINT0 <= handle < HANDLE_JOINT0 + 4:
            return twin.profile.joint_names[handle - HANDLE_JOINT0]
        if handle == HANDLE_PAD:
            return PAD_ALIASES[0]
        if HANDLE_OBJECT0 <= handle < HANDLE_OBJECT0 + len(twin.config.objects):
            return twin.config.objects[handle - HANDLE_OBJECT0].name
        raise UnknownName(
            f"object handle {handle} does not exist; handles are {self._handle_list()}"
        )

    def _handle_list(self) -> str:
        n = len(self.scene.twin.config.objects)
        objs = f", objects {HANDLE_OBJECT0}..{HANDLE_OBJECT0 + n - 1}" if n else ""
        return (
            f"robot {HANDLE_ROBOT}, joints {HANDLE_JOINT0}..{HANDLE_JOINT0 + 3}, pad "
            f"{HANDLE_PAD}{objs}"
        )

    def _joint(self, handle: int) -> int:
        if HANDLE_JOINT0 <= handle < HANDLE_JOINT0 + 4:
            return handle - HANDLE_JOINT0
        name = self.name_of(handle)  # raises for an unknown handle
        raise RequestError(
            f"object {handle} ({name}) is not a joint; joints are "
            f"{HANDLE_JOINT0}..{HANDLE_JOINT0 + 3}"
        )

    # -- objects -----------------------------------------------------------------------------
    def get_object(self, path: str, options: dict) -> int:
        try:
            return self.resolve(path)
        except UnknownName:
            if options.get("noError"):
                return -1
            raise

    def get_object_handle(self, name: str) -> int:
        return self.resolve(name)

    def get_object_alias(self, handle: int, options: int) -> str:
        return self.name_of(handle)

    def pose(self, handle: int) -> tuple[float, ...]:
        """World pose (x, y, z, qx, qy, qz, qw) of an object, from the current frame."""
        twin = self.scene.twin
        frame = twin.frame
        p = twin.profile
        if handle == HANDLE_ROBOT or handle == HANDLE_WORLD:
            return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        if handle == HANDLE_PAD:
            return frame.pad_pose
        if HANDLE_OBJECT0 <= handle < HANDLE_OBJECT0 + len(twin.config.objects):
            return frame.object_poses[handle - HANDLE_OBJECT0]
        j = self._joint(handle)
        q1, q2 = kinematics.link_angles(p, frame.joint_q)  # link directions in the profile's frame
        pad = kinematics.fk(p, frame.joint_q)
        if j == 0:
            return (0.0, 0.0, p.shoulder_height_m, *yaw_quat(q1))
        if j == 1:
            # math, not numpy: numpy's cos/sin take SIMD paths that differ by CPU, and a client acts
            # on this
            return (
                p.link1_m * math.cos(q1),
                p.link1_m * math.sin(q1),
                p.elbow_height_m,
                *yaw_quat(q2),
            )
        if j == 2:
            return (pad.x_m, pad.y_m, p.elbow_height_m, *yaw_quat(q2))
        return (pad.x_m, pad.y_m, pad.z_m + p.pad_length_m, *yaw_quat(pad.heading_rad))

    def _relative_pose(self, handle: int, rel: int) -> tuple[float, ...]:
        pose = self.pose(handle)
        if rel == HANDLE_WORLD:
            return pose
        if rel == -11:  # sim.handle_parent: the robot base is every object's root
            rel = HANDLE_ROBOT
        base = self.pose(rel) if rel != handle else pose
        inv = (-base[3], -base[4], -base[5], base[6])
        d = rotate(inv, (pose[0] - base[0], pose[1] - base[1], pose[2] - base[2]))
        return (*d, *quat_mul(inv, pose[3:]))

    # -- joints ------------------------------------------------------------------------------
    def set_joint_target_position(self, handle: int, q: float, motion: list) -> None:
        if motion:
            raise RequestError(
                f"sim.setJointTargetPosition: motionParams ({brief_value(motion)}) are "
                f"not supported; "
                "pass none (the joint moves at its maximum velocity)"
            )
        self.scene.twin.set_joint_target(self._joint(handle), q)

    def set_joint_position(self, handle: int, q: float) -> None:
        self.scene.twin.set_joint_position(self._joint(handle), q)

    def get_joint_position(self, handle: int) -> float:
        """As CoppeliaSim reports it: a cyclic revolute joint (the seeds' scenes) in -pi..pi."""
        j = self._joint(handle)
        q = self.scene.twin.frame.joint_q[j]
        if self.scene.twin.profile.revolute_cyclic and ROLES[j] != "z":
            q = kinematics.wrap_rad(q)
        return q

    def get_joint_target_position(self, handle: int) -> float:
        return self.scene.twin.targets[self._joint(handle)]

    def get_joint_velocity(self, handle: int) -> float:
        return self.scene.twin.frame.joint_qd[self._joint(handle)]

    # -- signals -----------------------------------------------------------------------------
    def set_int_signal(self, name: str, value: int) -> None:
        if not INT32[0] <= value <= INT32[1]:
            raise RequestError(
                f"signal {brief_value(name)} value {brief_value(value)} is outside the int32 range "
                f"{INT32[0]}..{INT32[1]}"
            )
        signals = self.scene.twin.signals
        if name not in signals and len(signals) >= MAX_SIGNALS:
            raise RequestError(
                f"signal {brief_value(name)}: the scene already holds {MAX_SIGNALS} "
                f"signals (the limit); "
                "clear one first"
            )
        self.scene.twin.set_signal(name, value)

    def get_int_signal(self, name: str) -> int | None:
        return self.scene.twin.get_signal(name)

    def clear_int_signal(self, name: str) -> None:
        if self.scene.twin.get_signal(name) is not None:
            self.scene.twin.set_signal(name, None)

    # -- simulation --------------------------------------------------------------------------
    def start_simulation(self) -> int:
        self.scene.start()
        return 1

    def stop_simulation(self) -> int:
        self.scene.stop()
        return 1

    def pause_simulation(self) -> int:
        self.scene.pause()
        return 1

    def add_log(self, verbosity: int, message: str) -> None:
        level = VERBOSITY_NAMES.get(verbosity, str(verbosity))
        self.scene.log(f"[{level}] {self.client}: {printable(message)}")  # escaped: one status line
        self.scene.twin.event("log", message=message, verbosity=verbosity, client=self.client)

    def info(self) -> dict:
        """The map zmqRemoteApi.info returns for 'sim': callables and constants."""
        out: dict = {name[4:]: {"func": {}} for name in self.functions}
        out["step"] = {"func": {}}
        out["setStepping"] = {"func": {}}
        out.update({k: {"const": v} for k, v in CONSTANTS.items()})
        return dict(sorted(out.items()))


def _euler_xyz(q: tuple[float, ...]) -> tuple[float, float, float]:
    """CoppeliaSim's Euler angles (alpha, beta, gamma): R = Rx(alpha) Ry(beta) Rz(gamma)."""
    x, y, z, w = q
    r02 = 2 * (x * z + w * y)
    r12 = 2 * (y * z - w * x)
    r22 = 1 - 2 * (x * x + y * y)
    r01 = 2 * (x * y - w * z)
    r00 = 1 - 2 * (y * y + z * z)
    beta = math.asin(max(-1.0, min(1.0, r02)))
    return (math.atan2(-r12, r22), beta, math.atan2(-r01, r00))
