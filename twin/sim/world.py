"""The PyBullet boundary: the only module that imports pybullet.

Builds the scene in one fixed order (floor, robot, objects in scene order), sets every engine
parameter explicitly, steps with a fixed time step and reads state. Never uses real-time mode,
never calls getLinkState with computeForwardKinematics (that changes later physics).
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from collections.abc import Callable
from functools import partial

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError
from twin.model.types import NO_BODY
from twin.robot.urdf import urdf_text

NO_CONSTRAINT = -1
NO_CLIENT = -1  # a closed World's client id: PyBullet refuses it as "not connected"
# DIRECT clients of closed Worlds, kept for this process's next ones (World._direct_client)
_SPARE_CLIENTS: list[int] = []
_MAX_SPARE = 1
# The solver's residual threshold is EngineParams.solver_residual_threshold (recorded with the run):
# at PyBullet's default 1e-7 a resting box creeps (tests/test_long_run.py measures it).
# The floor is a static box, not a GEOM_PLANE: PyBullet builds a box-on-plane contact one corner per
# step, so a box set down on a plane slides 0.03-0.33 mm diagonally (more the higher it drops from);
# on a box floor it lands where it is put.
FLOOR_HALF_EXTENTS_M = (5.0, 5.0, 0.05)
_NO_WRENCH = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def _import_pybullet_quietly():
    """pybullet prints its build time from C at import; keep our stdout/stderr clean of it."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in saved:
            os.dup2(devnull, fd)
        import pybullet

        ctypes.CDLL(None).fflush(None)  # C stdio may buffer the message when stdout is a pipe
    finally:
        for fd, keep in saved.items():
            os.dup2(keep, fd)
            os.close(keep)
        os.close(devnull)
    return pybullet


pb = _import_pybullet_quietly()
# the calls made every step, bound once (a module attribute lookup less each)
_step_simulation, _joint_states, _base_pose = (
    pb.stepSimulation,
    pb.getJointStates,
    pb.getBasePositionAndOrientation,
)


class World:
    """A PyBullet client holding one robot and the scene's objects."""

    def __init__(self, config: TwinConfig, *, gui: bool = False) -> None:
        self.config = config
        self.gui = gui
        if gui:
            _require_display()
        self.client = pb.connect(pb.GUI) if gui else self._direct_client()
        self._closed = False
        if self.client < 0:
            raise ConfigError("cannot open a PyBullet window; run without --gui or under a display")
        if gui:
            pb.configureDebugVisualizer(
                pb.COV_ENABLE_KEYBOARD_SHORTCUTS, 0, physicsClientId=self.client
            )
        self.urdf_text = ""
        self.robot = -1
        self.joints: tuple[int, ...] = ()
        self.pad_link = -1
        self.object_ids: tuple[int, ...] = ()
        self._constraint = NO_CONSTRAINT
        self._keys_down: set[int] = set()
        try:
            self.build()
            if gui:
                self._frame_workspace()
        except pb.error as err:  # e.g. the window was closed (Esc) while the scene was loading
            self.close()
            raise ConfigError(f"PyBullet failed while building the scene: {err}") from err
        except BaseException:
            self.close()  # a half-built world must not keep its PyBullet client (or window)
            raise

    # -- building ---------------------------------------------------------------------------
    def build(self) -> None:
        """Build the scene in its fixed order: reset, engine parameters, floor, robot, objects
        (once, at start)."""
        c = self.client
        pb.resetSimulation(physicsClientId=c)
        self._constraint = NO_CONSTRAINT
        self._overlapping: list[tuple[int, int]] = []  # (link, body) pairs released while touching
        self._bare_step = partial(_step_simulation, c)  # stepper(): made once, not at every call
        e = self.config.engine
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self.config.dt_s,
            numSolverIterations=e.num_solver_iterations,
            numSubSteps=0,
            deterministicOverlappingPairs=e.deterministic_overlapping_pairs,
            solverResidualThreshold=e.solver_residual_threshold,
            physicsClientId=c,
        )
        pb.setGravity(*e.gravity_m_s2, physicsClientId=c)
        pb.setRealTimeSimulation(0, physicsClientId=c)
        floor = pb.createCollisionShape(
            pb.GEOM_BOX, halfExtents=FLOOR_HALF_EXTENTS_M, physicsClientId=c
        )
        # top at z = 0
        pb.createMultiBody(0, floor, -1, (0.0, 0.0, -FLOOR_HALF_EXTENTS_M[2]), physicsClientId=c)
        self._load_robot()
        self.object_ids = tuple(self._create_object(o) for o in self.config.objects)

    def _load_robot(self) -> None:
        profile = self.config.profile
        flags = pb.URDF_USE_INERTIA_FROM_FILE
        self.urdf_text = urdf_text(profile)
        if profile.urdf_path:
            try:
                self.robot = pb.loadURDF(
                    profile.urdf_path, useFixedBase=True, flags=flags, physicsClientId=self.client
                )
            except pb.error as err:
                raise ConfigError(
                    f"PyBullet cannot load the URDF {profile.urdf_path!r} of robot "
                    f"{profile.name!r} (a mesh missing or unreadable?): {err}"
                ) from err
        else:
            fd, path = tempfile.mkstemp(suffix=".urdf", prefix=f"twin_{profile.name}_")
            try:
                with os.fdopen(fd, "w") as f:
                    f.write(self.urdf_text)
                self.robot = pb.loadURDF(
                    path, useFixedBase=True, flags=flags, physicsClientId=self.client
                )
            finally:
                os.unlink(path)
        by_name: dict[str, int] = {}
        link_by_name: dict[str, int] = {}
        for j in range(pb.getNumJoints(self.robot, physicsClientId=self.client)):
            info = pb.getJointInfo(self.robot, j, physicsClientId=self.client)
            by_name[info[1].decode()] = j
            link_by_name[info[12].decode()] = j
        try:
            self.joints = tuple(by_name[n] for n in profile.joint_names)
        except KeyError as err:
            raise ConfigError(f"robot {profile.name!r} URDF lacks joint {err.args[0]!r}") from err
        self.pad_link = link_by_name.get(profile.pad_link or "suctionPad", self.joints[3])
        e = self.config.engine
        for j, v_max, f_max in zip(
            self.joints, self.max_velocities(), self.max_forces(), strict=True
        ):
            pb.changeDynamics(
                self.robot, j, linearDamping=0.0, angularDamping=0.0, physicsClientId=self.client
            )
            pb.setJointMotorControl2(
                self.robot,
                j,
                pb.POSITION_CONTROL,
                targetPosition=0.0,
                force=f_max,
                maxVelocity=v_max,
                positionGain=e.position_gain,
                velocityGain=e.velocity_gain,
                physicsClientId=self.client,
            )

    def max_velocities(self) -> tuple[float, ...]:
        """Each joint's motor speed limit from the profile: rad/s, rad/s, m/s, rad/s."""
        p = self.config.profile
        return (p.revolute_max_velocity_rad_s,) * 2 + (
            p.prismatic_max_velocity_m_s,
            p.revolute_max_velocity_rad_s,
        )

    def max_forces(self) -> tuple[float, ...]:
        """Each joint's motor force limit from the profile: N·m, N·m, N, N·m."""
        p = self.config.profile
        return (p.revolute_max_torque_nm,) * 2 + (p.prismatic_max_force_n, p.revolute_max_torque_nm)

    def _create_object(self, o) -> int:
        c = self.client
        half = [s / 2 for s in o.size_m]
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
        vis = pb.createVisualShape(
            pb.GEOM_BOX, halfExtents=half, rgbaColor=list(o.rgba), physicsClientId=c
        )
        orn = pb.getQuaternionFromEuler((0.0, 0.0, o.yaw_rad))
        body = pb.createMultiBody(o.mass_kg, col, vis, list(o.pos_m), orn, physicsClientId=c)
        pb.changeDynamics(body, -1, lateralFriction=o.friction, physicsClientId=c)
        return body

    # -- acting -----------------------------------------------------------------------------
    def set_motor(self, joint: int, target: float, max_velocity: float) -> None:
        e = self.config.engine
        pb.setJointMotorControl2(
            self.robot,
            self.joints[joint],
            pb.POSITION_CONTROL,
            targetPosition=target,
            force=self.max_forces()[joint],
            maxVelocity=max_velocity,
            positionGain=e.position_gain,
            velocityGain=e.velocity_gain,
            physicsClientId=self.client,
        )

    def reset_joint(self, joint: int, q: float) -> None:
        """Kinematic set (like simxSetJointPosition): position jumps, velocity zero."""
        pb.resetJointState(self.robot, self.joints[joint], q, 0.0, physicsClientId=self.client)

    # The calls made every step pass the client positionally: pybullet then skips matching keyword
    # names (measured: getJointStates 1.43 -> 1.28 us, getBasePositionAndOrientation 0.69 -> 0.56
    # us).
    def step(self) -> None:
        _step_simulation(self.client)
        if self._overlapping:
            self._collide_once_apart()

    def stepper(self) -> Callable[[], object]:
        """What step() does, as a call to make every step until the next attach or detach: with no
        released object still overlapping the robot, PyBullet's step itself, without a Python call
        around it (the twin's loop asks again after every suction change)."""
        return self.step if self._overlapping else self._bare_step

    # -- reading ----------------------------------------------------------------------------
    def state(self) -> tuple:
        """Everything a Frame reads from the engine, in one call (the twin makes one every step):
        the four joints' positions, velocities and applied motor efforts (float64), each object's
        pose, and the hold's force and torque (_hold_wrench)."""
        c = self.client
        (q0, v0, _, e0), (q1, v1, _, e1), (q2, v2, _, e2), (q3, v3, _, e3) = _joint_states(
            self.robot, self.joints, c
        )
        # the usual scene, one box: 4.3k CPU instructions a step fewer (callgrind)
        if len(self.object_ids) == 1:
            p, o = _base_pose(self.object_ids[0], c)
            poses = (p + o,)
        else:
            poses = tuple([p + o for p, o in [_base_pose(body, c) for body in self.object_ids]])
        force, torque = (
            _NO_WRENCH if self._constraint == NO_CONSTRAINT else self._hold_wrench(poses)
        )
        return (q0, q1, q2, q3), (v0, v1, v2, v3), (e0, e1, e2, e3), poses, force, torque

    def ray_down(self, x_m: float, y_m: float, z_from_m: float, length_m: float) -> int:
        """The scene object (index) a vertical ray going down from z_from_m hits first, or
        NO_BODY."""
        body = pb.rayTest(
            (x_m, y_m, z_from_m), (x_m, y_m, z_from_m - length_m), physicsClientId=self.client
        )[0][0]
        return self.object_ids.index(body) if body in self.object_ids else NO_BODY

    # -- holding ----------------------------------------------------------------------------
    def attach(
        self, obj: int, pad_root_pos_m: tuple[float, float, float], pad_yaw_rad: float
    ) -> None:
        """Fix object `obj` rigidly to the pad where it is now. The pad root's pose comes from the
        joint angles (exact), not from getLinkState (float32 and one step old)."""
        c = self.client
        body = self.object_ids[obj]
        link_orn = pb.getQuaternionFromEuler((0.0, 0.0, pad_yaw_rad))
        com_local_pos, com_local_orn = pb.getDynamicsInfo(
            self.robot, self.pad_link, physicsClientId=c
        )[3:5]
        com_pos, com_orn = pb.multiplyTransforms(
            pad_root_pos_m, link_orn, com_local_pos, com_local_orn
        )
        obj_pos, obj_orn = pb.getBasePositionAndOrientation(body, physicsClientId=c)
        inv_pos, inv_orn = pb.invertTransform(com_pos, com_orn)
        rel_pos, rel_orn = pb.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)
        self._constraint = pb.createConstraint(
            parentBodyUniqueId=self.robot,
            parentLinkIndex=self.pad_link,
            childBodyUniqueId=body,
            childLinkIndex=-1,
            jointType=pb.JOINT_FIXED,
            jointAxis=(0, 0, 0),
            parentFramePosition=rel_pos,
            childFramePosition=(0, 0, 0),
            parentFrameOrientation=rel_orn,
            childFrameOrientation=(0, 0, 0, 1),
            physicsClientId=c,
        )
        pb.changeConstraint(self._constraint, maxForce=1e4, physicsClientId=c)
        self._held_body = body
        self._held_index = obj
        self._robot_collides_with(body, False)  # a held object is part of the tool, like its links
        self._overlapping = [(link, b) for link, b in self._overlapping if b != body]

    def detach(self) -> None:
        if self._constraint != NO_CONSTRAINT:
            pb.removeConstraint(self._constraint, physicsClientId=self.client)
            self._constraint = NO_CONSTRAINT
            self._restore_collisions(self._held_body)

    def _restore_collisions(self, body: int) -> None:
        """A released object collides with the robot again, except with links it overlaps now (a box
        lifted into the arm's volume would be shot out); those pairs wait until they are apart."""
        links = range(-1, pb.getNumJoints(self.robot, physicsClientId=self.client))
        self._overlapping.extend((link, body) for link in links)
        self._collide_once_apart()

    def _collide_once_apart(self) -> None:
        """Turn collisions back on for the pairs in _overlapping that no longer overlap."""
        c = self.client
        still = []
        for link, body in self._overlapping:
            if pb.getClosestPoints(self.robot, body, 0.0, linkIndexA=link, physicsClientId=c):
                still.append((link, body))
            else:
                pb.setCollisionFilterPair(self.robot, body, link, -1, 1, physicsClientId=c)
        self._overlapping = still

    def _robot_collides_with(self, body: int, enable: bool) -> None:
        for link in range(-1, pb.getNumJoints(self.robot, physicsClientId=self.client)):
            pb.setCollisionFilterPair(
                self.robot, body, link, -1, int(enable), physicsClientId=self.client
            )

    def _hold_wrench(
        self, object_poses: tuple[tuple[float, ...], ...]
    ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Force (N) and torque (N·m, about the object's centre of mass) the pad applied to the held
        object in the last step, world frame (state() asks only while something is held). A box
        hanging still gets +m·g in z. object_poses: this step's object poses (the held object's
        orientation turns the torque).

        getConstraintState gives the reaction on the pad (minus the wrench on the object): the force
        along world axes, the torque along the constraint frame's axes, which are rigid with the
        object.
        """
        s = pb.getConstraintState(self._constraint, self.client)
        orn = object_poses[self._held_index][3:7]
        r = pb.getMatrixFromQuaternion(orn)  # row-major: world = r @ constraint frame
        tx, ty, tz = -s[3], -s[4], -s[5]
        torque = (
            r[0] * tx + r[1] * ty + r[2] * tz,
            r[3] * tx + r[4] * ty + r[5] * tz,
            r[6] * tx + r[7] * ty + r[8] * tz,
        )
        return (-s[0], -s[1], -s[2]), torque

    def _frame_workspace(self) -> None:
        """Open the window on the arm's reach with PyBullet's side panels and camera previews
        hidden: by default it shows the whole floor, the robot small in its middle, between debug
        panels."""
        c = self.client
        for flag in (
            pb.COV_ENABLE_GUI,
            pb.COV_ENABLE_RGB_BUFFER_PREVIEW,
            pb.COV_ENABLE_DEPTH_BUFFER_PREVIEW,
            pb.COV_ENABLE_SEGMENTATION_MARK_PREVIEW,
        ):
            pb.configureDebugVisualizer(flag, 0, physicsClientId=c)
        p = self.config.profile
        reach_m = p.link1_m + p.link2_m
        pb.resetDebugVisualizerCamera(
            cameraDistance=1.8 * reach_m,
            cameraYaw=45.0,
            cameraPitch=-40.0,
            cameraTargetPosition=(0.0, 0.0, 0.5 * p.elbow_height_m),
            physicsClientId=c,
        )

    def window_camera(self) -> dict:
        """The window's camera: distance_m, yaw_deg, pitch_deg, target_m (headless: {})."""
        if not self.gui:
            return {}
        info = pb.getDebugVisualizerCamera(physicsClientId=self.client)
        return {
            "distance_m": info[10],
            "yaw_deg": info[8],
            "pitch_deg": info[9],
            "target_m": tuple(info[11]),
        }

    # -- the window's keyboard (teleop) -------------------------------------------------------
    def keyboard_events(self) -> list[str]:
        """Names of the keys pressed in the PyBullet window since the last call ([] headless)."""
        if not self.gui:
            return []
        return decode_key_events(pb.getKeyboardEvents(physicsClientId=self.client), self._keys_down)

    def connected(self) -> bool:
        """False once the PyBullet window has been closed."""
        return bool(pb.isConnected(self.client))

    def close(self) -> None:
        """Let go of the PyBullet client: a plain headless world's is kept for the next World of
        this process (_direct_client), any other disconnected. Idempotent."""
        if self._closed or not pb.isConnected(self.client):
            return
        self._closed = True
        if self._reuses_clients() and len(_SPARE_CLIENTS) < _MAX_SPARE:
            _SPARE_CLIENTS.append(self.client)  # build() resets it before anything else
        else:
            pb.disconnect(self.client)
        # a call on this closed World fails as on a disconnected one, never reaching the client's
        # next World
        self.client = NO_CLIENT

    def _reuses_clients(self) -> bool:
        """A headless World itself (not a render world, whose renderer keeps state of its own)."""
        return not self.gui and type(self) is World

    def _direct_client(self) -> int:
        """A DIRECT client: one a closed World left, else a new one. Connecting is most of building
        a Twin (14 of 18 ms here); build() starts with resetSimulation, after which a client steps
        bit for bit as a fresh one does (docs: determinism; the goldens hold it)."""
        while self._reuses_clients() and _SPARE_CLIENTS:
            client = _SPARE_CLIENTS.pop()
            if pb.isConnected(client):
                return client
        return pb.connect(pb.DIRECT)


def _require_display() -> None:
    """PyBullet's GUI calls exit() when it cannot reach an X server: check for one first (Linux)."""
    if not sys.platform.startswith("linux"):
        return
    display = os.environ.get("DISPLAY", "")
    if not display:
        raise ConfigError(
            "--gui needs a display but DISPLAY is not set; run without --gui or under Xvfb"
        )
    try:
        xlib = ctypes.CDLL("libX11.so.6")
    except OSError as err:
        raise ConfigError(
            f"--gui needs libX11 (X11 client library), which cannot be loaded: {err}"
        ) from err
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    handle = xlib.XOpenDisplay(display.encode())
    if not handle:
        raise ConfigError(
            f"--gui cannot connect to the X display DISPLAY={display!r}; run without "
            f"--gui or under Xvfb"
        )
    xlib.XCloseDisplay(handle)


_KEY_NAMES = {
    pb.B3G_UP_ARROW: "up",
    pb.B3G_DOWN_ARROW: "down",
    pb.B3G_LEFT_ARROW: "left",
    pb.B3G_RIGHT_ARROW: "right",
    pb.B3G_SPACE: "space",
    pb.B3G_RETURN: "enter",
    9: "tab",
    pb.B3G_BACKSPACE: "backspace",
    pb.B3G_DELETE: "delete",
    pb.B3G_INSERT: "insert",
    pb.B3G_HOME: "home",
    pb.B3G_END: "end",
    pb.B3G_PAGE_UP: "pageup",
    pb.B3G_PAGE_DOWN: "pagedown",
    27: "esc",
    **{pb.B3G_F1 + i: f"f{i + 1}" for i in range(12)},
}


def decode_key_events(events: dict[int, int], keys_down: set[int]) -> list[str]:
    """Key names from one getKeyboardEvents() dict. A press counts once: when it is triggered, or
    when only its release arrives (a quick tap may show up only as released). Shift+letter gives the
    capital when Shift is down, or was pressed, in the same poll."""
    shift = bool(events.get(pb.B3G_SHIFT, 0) & (pb.KEY_IS_DOWN | pb.KEY_WAS_TRIGGERED))
    names = []
    for code, state in sorted(events.items()):
        name = _KEY_NAMES.get(code) or (chr(code) if 33 <= code <= 126 else None)
        pressed = False
        if state & pb.KEY_WAS_TRIGGERED:
            pressed = code not in keys_down
            keys_down.add(code)
        if state & pb.KEY_WAS_RELEASED:
            pressed = pressed or code not in keys_down
            keys_down.discard(code)
        if pressed and name is not None:
            names.append(name.upper() if shift and len(name) == 1 else name)
    return names


def pybullet_version() -> str:
    return str(pb.getAPIVersion())


def engine_versions() -> dict[str, str]:
    """The engine's own version, for a recorder to name in its file (record/ never imports sim/)."""
    return {"pybullet_api": pybullet_version()}
