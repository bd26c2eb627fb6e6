"""Twin: the API that tasks, the keyboard and remote clients call.

Every input becomes a Command stamped with the step it takes effect at; every physics step
produces a Frame; every discrete happening an Event. All three go to the sinks, in order.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from types import MappingProxyType
from typing import Any

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, UnknownName
from twin.model.images import CameraImage
from twin.model.json_values import event_data, finite_number
from twin.model.keymaps import KeyPlayer
from twin.model.sink import Sink, reads_pad_pose
from twin.model.types import COMMAND_ARGS, NO_BODY, Command, Event, Frame
from twin.robot import kinematics
from twin.sim.keyhands import KeyHands
from twin.sim.motions import Motions, Z
from twin.sim.suction import Suction
from twin.sim.world import World

_new_frame = tuple.__new__


class Twin(Motions):
    """A headless (or windowed) PyBullet twin of a SCARA robot, advanced in simulated time.

    A task receives one and drives it through the methods below; every call that changes the twin
    is a Command, recorded and replayed at the step it was made.
    """

    def __init__(
        self,
        config: TwinConfig | None = None,
        *,
        gui: bool = False,
        sinks: list[Sink] = (),
        camera_background: bool | None = None,
    ) -> None:
        """Build the scene and read the first Frame (step 0), which goes to every sink.

        Args:
            config: The robot profile, scene, suction pad, cameras and time step; the default
                `TwinConfig()` is the MTB robot with one box.
            gui: Open PyBullet's window (teleoperation) instead of running headless.
            sinks: Receivers of every Frame, Command, Event and picture (the recorders).
            camera_background: Draw the cameras' pictures in a render process (True), in the
                stepping thread (False), or in a render process unless this process is a daemon
                (None, which may not fork).
        """
        self.config = config or TwinConfig()
        self.profile = self.config.profile
        self._world = World(self.config, gui=gui)
        self.suction_pad = Suction(
            self.config.suction,
            self.profile.pad_length_m,
            self._world,
            tuple(o.size_m for o in self.config.objects),
        )
        self.sinks: tuple[Sink, ...] = tuple(sinks)  # fixed for the twin's life
        self.step_index = 0
        self._signals: dict[str, int] = {}
        # a tuple, replaced on a command: every Frame shares it
        self._targets = (0.0, 0.0, 0.0, 0.0)
        self._max_velocities = list(self._world.max_velocities())
        self._limits = self.profile.joint_limits()
        self._suction_wanted = False  # any of the profile's suction signals is non-zero
        self._keys = KeyPlayer(self.config.keymap, self.profile)
        self._key_hands = KeyHands(self)
        self._said: Event | None = None  # the Event the last `event` Command emitted
        self._pad_pose = kinematics.pad_pose_function(self.profile)
        self._camera_renderer = self._add_cameras(camera_background)
        # the pad pose only while a sink or camera reads it (else the `frame` property works it out)
        self._pads_each_step = self._camera_renderer is not None or any(
            reads_pad_pose(s) for s in self.sinks
        )
        self._frame = self._read_frame()
        self._emit_frame(self._frame)

    # -- read-only views: the twin changes only through Commands (apply), so every input is recorded
    # --
    @property
    def frame(self) -> Frame:
        """The latest Frame: the state after the last step (step 0 before any)."""
        f = self._frame
        if f.pad_pose is None:  # no sink read it as it went by: worked out now, once
            f = self._frame = f._replace(pad_pose=self._pad_pose(f.joint_q))
        return f

    @property
    def targets(self) -> tuple[float, ...]:
        """Each joint's motor target (rad | m), in profile joint order."""
        return self._targets

    @property
    def signals(self) -> Mapping[str, int]:
        return MappingProxyType(self._signals)

    @property
    def max_velocities(self) -> tuple[float, ...]:
        return tuple(self._max_velocities)

    @property
    def limits(self) -> tuple[tuple[float, float], ...]:
        return tuple(self._limits)

    @property
    def gui(self) -> bool:
        """True when the twin draws a PyBullet window."""
        return self._world.gui

    def window_open(self) -> bool:
        """False once the user has closed the PyBullet window (always True headless)."""
        return self._world.connected()

    def window_keys(self) -> list[str]:
        """Keys typed into the PyBullet window since the last call (teleop --gui)."""
        return self._world.keyboard_events()

    # -- time -------------------------------------------------------------------------------
    @property
    def t_ns(self) -> int:
        return self.step_index * self.config.dt_ns

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    def step(self, n: int = 1) -> Frame:
        """Advance n physics steps: the suction rule, physics, then a Frame to every sink.

        Args:
            n: How many physics steps (each `config.dt_ns` of simulated time).

        Returns:
            The Frame after the last step (also `twin.frame`).
        """
        for _ in self._stepping(n):
            pass
        return self.frame

    def _stepping(self, n: int) -> Iterator[Frame]:
        """Advance n physics steps, yielding each Frame once every sink has it: for a caller that
        looks at every Frame (settle), a generator's resume costs a fraction of a step() call. The
        Frame is made here as _read_frame makes it (written out: a call less a step), but for its
        pad pose while no sink reads that."""
        sinks, pad_model, world = self.sinks, self.suction_pad, self._world
        renderer, state, pad_pose = self._camera_renderer, world.state, self._pad_pose
        pads = self._pads_each_step
        world_step, dt_ns = world.stepper(), self.config.dt_ns
        for _ in range(n):
            # an idle pad, or one holding on, has nothing to do
            if self._suction_wanted is not pad_model.idle_on:
                for ev in pad_model.update(self._suction_wanted, self.frame, self._heading):
                    self._emit(ev.kind, self._body_name(ev.body), ev.message)
                world_step = world.stepper()  # a hold taken or let go changes how the world steps
            world_step()
            step = self.step_index = self.step_index + 1
            q, qd, effort, poses, force, torque = state()
            f = self._frame = _new_frame(
                Frame,
                (
                    step,
                    step * dt_ns,
                    q,
                    qd,
                    effort,
                    self._targets,
                    pad_model.on,
                    pad_model.sensed,
                    pad_model.held,
                    force,
                    torque,
                    pad_pose(q) if pads else None,
                    poses,
                ),
            )
            for s in sinks:
                s.on_frame(f)
            # after every sink: a picture reaches them after the frame it shows
            if renderer is not None:
                renderer.on_frame(f)
            yield f

    def wait(self, seconds: float) -> Frame:
        """Let simulated time pass (the seeds' `sim.wait`), rounded to whole steps.

        Args:
            seconds: Simulated seconds, a finite number >= 0.

        Returns:
            The Frame after the last step.

        Raises:
            ConfigError: `seconds` is negative or not a finite number.
        """
        if _number(seconds, "wait") < 0:
            raise ConfigError(f"wait of {seconds} s is invalid; expected a finite number >= 0")
        return self.step(round(seconds * 1e9 / self.config.dt_ns))

    # -- state ------------------------------------------------------------------------------
    def _read_frame(self) -> Frame:
        q, qd, effort, poses, force, torque = self._world.state()
        sp = self.suction_pad
        step = self.step_index
        # tuple.__new__, not Frame(...): a NamedTuple's __new__ is a Python function (0.2 us more a
        # step)
        return _new_frame(
            Frame,
            (
                step,
                step * self.config.dt_ns,
                q,
                qd,
                effort,
                self._targets,
                sp.on,
                sp.sensed,
                sp.held,
                force,
                torque,
                self._pad_pose(q),
                poses,
            ),
        )

    def _heading(self, f: Frame) -> float:
        return kinematics.heading(self.profile, f.joint_q)

    def _emit_frame(self, frame: Frame) -> None:
        for s in self.sinks:
            s.on_frame(frame)
        if self._camera_renderer is not None:
            self._camera_renderer.on_frame(frame)

    def _send_image(self, image: CameraImage) -> None:
        """A camera's picture, handed on by the renderer once its frame has reached every sink."""
        for s in self.sinks:
            s.on_image(image)

    def _body_name(self, index: int) -> str:
        return "" if index == NO_BODY else self.config.objects[index].name

    def object_index(self, name: str) -> int:
        """The index of a scene object in `frame.object_poses` and in events.

        Args:
            name: The object's name (a leading "/", as CoppeliaSim paths have, is ignored).

        Raises:
            UnknownName: No object has that name.
        """
        bare = name.lstrip("/")
        for i, o in enumerate(self.config.objects):
            if o.name == bare:
                return i
        raise UnknownName(
            f"unknown object {name!r}; expected one of {[o.name for o in self.config.objects]}"
        )

    def joint_position(self, joint: str | int) -> float:
        """A joint's position in the last Frame (rad, or m for the Z joint).

        Args:
            joint: A joint name, a role (`shoulder`, `elbow`, `z`, `wrist`) or an index 0..3.

        Raises:
            UnknownName: No such joint.
        """
        return self.frame.joint_q[self._joint(joint)]

    def pad_position(self) -> tuple[float, float, float]:
        """The pad tip's (centre of the cup's face) x, y, z in metres, world frame."""
        p = self.frame.pad_pose
        return (p[0], p[1], p[2])

    def object_pose(self, name: str) -> tuple[float, ...]:
        """A scene object's pose in the last Frame: x, y, z (m), qx, qy, qz, qw.

        Raises:
            UnknownName: No object has that name.
        """
        return self.frame.object_poses[self.object_index(name)]

    def get_signal(self, name: str) -> int | None:
        """An integer signal's value, or None when it is not set."""
        return self._signals.get(name)

    # -- events -----------------------------------------------------------------------------
    def event(self, kind: str, body: str = "", message: str = "", **data: Any) -> Event:
        """Say something now (a task's phase, a placement report, a client's log line).

        The Event travels as an `event` Command, so a replay says it again at the same step.

        Args:
            kind: What happened, a non-empty string (`placed`, `phase`, ...).
            body: The scene object it concerns, if any.
            message: A line for people.
            **data: JSON data (numpy values become numbers and lists; a non-finite number null).

        Returns:
            The Event as the sinks received it.

        Raises:
            ConfigError: `kind` is empty or not a string, or `data` is not JSON data.
        """
        if not isinstance(kind, str) or not kind:
            raise ConfigError(f"event kind {kind!r:.40} is invalid; expected a non-empty string")
        args = {
            "kind": kind,
            "body": str(body),
            "message": str(message),
            "data": event_data(kind, data),
        }
        self.apply(Command(self.step_index, "event", args))
        return self._said

    def _emit(
        self, kind: str, body: str = "", message: str = "", data: dict | None = None
    ) -> Event:
        """An Event the twin itself raises while stepping or applying a Command (attach, release,
        joint_limit, ...): replay regenerates these, so they are not Commands."""
        return self._send_now(kind, body, message, event_data(kind, data or {}))

    def _send_now(self, kind: str, body: str, message: str, data: dict) -> Event:
        """An Event of this step to every sink."""
        return self._send(
            Event(
                step=self.step_index,
                t_ns=self.t_ns,
                kind=kind,
                body=body,
                message=message,
                data=data,
            )
        )

    def _send(self, ev: Event) -> Event:
        for s in self.sinks:
            s.on_event(ev)
        return ev

    def phase(self, name: str) -> None:
        """Mark a task phase (a `phase` event, shown in the log and the viewer).

        Args:
            name: The phase, e.g. "pick" or "place".
        """
        self.event("phase", message=name)

    # -- commands ---------------------------------------------------------------------------
    def apply(self, command: Command) -> None:
        """Validate and apply one Command now; replay feeds recorded Commands through here.

        Args:
            command: A Command stamped with the current step.

        Raises:
            ConfigError: The Command is for another step, of an unknown kind, or its arguments
                are missing or malformed.
        """
        if command.step != self.step_index:
            raise ConfigError(f"command for step {command.step} applied at step {self.step_index}")
        handler = self._COMMANDS.get(command.kind)
        if handler is None:
            raise ConfigError(
                f"unknown command kind {command.kind!r}; expected one of {sorted(self._COMMANDS)}"
            )
        expected = COMMAND_ARGS[command.kind]
        if not isinstance(command.args, dict) or sorted(command.args) != sorted(expected):
            raise ConfigError(
                f"{command.kind} command at step {command.step} has arguments "
                f"{command.args!r:.80}; "
                f"expected {', '.join(expected)}"
            )
        for s in self.sinks:
            s.on_command(command)
        try:
            handler(self, command.args)
        except (TypeError, ValueError, OverflowError) as err:  # a hand-edited or corrupt recording
            raise ConfigError(
                f"{command.kind} command at step {command.step} is malformed: {err}"
            ) from err

    def _command(self, kind: str, **args: Any) -> None:
        self.apply(Command(self.step_index, kind, args))

    def _joint(self, joint: str | int) -> int:
        if isinstance(joint, bool) or not isinstance(joint, (str, int)):
            raise UnknownName(f"joint {joint!r} is neither a name nor an index 0..3")
        if isinstance(joint, int):
            if not 0 <= joint < 4:
                raise UnknownName(f"joint index {joint} is out of range; expected 0..3")
            return joint
        return self.profile.joint_index(joint)

    def set_joint_target(self, joint: str | int, q: float) -> None:
        """Drive a joint's motor toward q at its maximum velocity and force.

        A target outside the joint's limits is clamped, with a `joint_limit` event.

        Args:
            joint: A joint name, a role (`shoulder`, `elbow`, `z`, `wrist`) or an index 0..3.
            q: The target, rad (m for the Z joint).

        Raises:
            UnknownName: No such joint.
            ConfigError: `q` is not a finite number.
        """
        self._command(
            "joint_target",
            joint=self.profile.joint_names[self._joint(joint)],
            q=_number(q, "joint target"),
        )

    def set_joint_targets(self, targets: dict[str, float]) -> None:
        """`set_joint_target` for each joint of `targets` (joint -> q), in its order."""
        for joint, q in targets.items():
            self.set_joint_target(joint, q)

    def set_joint_position(self, joint: str | int, q: float) -> None:
        """Set a joint's position at once (kinematic), as `sim.setJointPosition` does.

        Args:
            joint: A joint name, a role or an index 0..3.
            q: The position, rad (m for the Z joint).

        Raises:
            UnknownName: No such joint.
            ConfigError: `q` is not a finite number.
        """
        self._command(
            "joint_position",
            joint=self.profile.joint_names[self._joint(joint)],
            q=_number(q, "joint position"),
        )

    def set_joint_max_velocity(self, joint: str | int, v: float) -> None:
        """Change the speed a joint's motor drives at.

        Args:
            joint: A joint name, a role or an index 0..3.
            v: The maximum velocity, rad/s (m/s for the Z joint), > 0.

        Raises:
            UnknownName: No such joint.
            ConfigError: `v` is not a finite number > 0.
        """
        v = _number(v, "maximum velocity")
        if v <= 0:
            raise ConfigError(f"maximum velocity {v} is invalid; expected > 0")
        self._command("joint_max_velocity", joint=self.profile.joint_names[self._joint(joint)], v=v)

    def set_signal(self, name: str, value: int | None) -> None:
        """Set, or clear, an integer signal; the profile's suction signals switch the pad.

        Args:
            name: The signal's name, a non-empty string.
            value: An integer, or None to clear it.

        Raises:
            ConfigError: The name is empty or the value is not an integer or None.
        """
        if not isinstance(name, str) or not name:
            raise ConfigError(f"signal name {name!r} is invalid; expected a non-empty string")
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise ConfigError(f"signal {name!r} value {value!r} is invalid; expected an integer")
        self._command("signal", name=name, value=value)

    def suction(self, on: bool) -> None:
        """Switch the suction pad on or off (the profile's first suction signal, 1 or 0).

        Args:
            on: True to draw air: the pad grips an object it senses under it.
        """
        self.set_signal(self.profile.suction_signals[0], 1 if on else 0)

    def press_key(self, key: str) -> None:
        """A key press, interpreted by the configured key map (teleop).

        Args:
            key: The key's name in the key map (`docs/how-to/teleop.md`).
        """
        self._command("key", key=str(key))

    # -- what each Command kind does: apply() looks the handler up in _COMMANDS -----------------
    def _clamped(self, joint: int, q: float) -> float:
        # CoppeliaSim's cyclic joint: the short way round
        if self.profile.revolute_cyclic and joint != Z:
            now = self.frame.joint_q[joint]
            return now + kinematics.wrap_rad(q - now)
        lo, hi = self._limits[joint]
        if lo <= q <= hi:
            return q
        clamped = min(hi, max(lo, q))
        name = self.profile.joint_names[joint]
        self._emit(
            "joint_limit",
            message=f"{name} target {q:.6g} beyond {lo:.6g}..{hi:.6g}; stopped at {clamped:.6g}",
            data={"joint": name, "requested": q, "limit": clamped},
        )
        return clamped

    def _do_joint_target(self, args: dict) -> None:
        j = self._joint(args["joint"])
        q = self._clamped(j, float(args["q"]))
        self._targets = _replaced(self._targets, j, q)
        self._world.set_motor(j, q, self._max_velocities[j])

    def _do_joint_position(self, args: dict) -> None:
        j = self._joint(args["joint"])
        q = self._clamped(j, float(args["q"]))
        self._targets = _replaced(self._targets, j, q)
        self._world.reset_joint(j, q)
        self._world.set_motor(j, q, self._max_velocities[j])
        self._frame = self._read_frame()  # the pad moved: later suction sensing must see it

    def _do_joint_max_velocity(self, args: dict) -> None:
        j = self._joint(args["joint"])
        self._max_velocities[j] = float(args["v"])
        self._world.set_motor(j, self._targets[j], self._max_velocities[j])

    def _do_signal(self, args: dict) -> None:
        if args["value"] is None:
            self._signals.pop(args["name"], None)
        else:
            self._signals[args["name"]] = int(args["value"])
        self._suction_wanted = any(self._signals.get(s, 0) for s in self.profile.suction_signals)

    def _do_event(self, args: dict) -> None:
        """What a task or client said (an `event` Command): emitted as the Event it describes."""
        kind, body, message, data = args["kind"], args["body"], args["message"], args["data"]
        if (
            not isinstance(kind, str)
            or not kind
            or not isinstance(body, str)
            or not isinstance(message, str)
        ):
            raise TypeError("kind, body and message must be strings (kind non-empty)")
        if not isinstance(data, dict):
            raise TypeError(f"data must be a JSON object, got {type(data).__name__}")
        # data is plain JSON already: made so by event(), or read from a recording
        self._said = self._send_now(kind, body, message, data)

    def _do_key(self, args: dict) -> None:
        """A key, played through the configured key map (model.keymaps.KeyPlayer)."""
        key = args["key"]
        if not self._keys.press(key, self._key_hands):
            self._emit(
                "key_unknown",
                message=f"key {key!r} is not in the key map; ignored",
                data={"key": key},
            )

    _COMMANDS = MappingProxyType(
        {  # one per COMMAND_ARGS kind
            "joint_target": _do_joint_target,
            "joint_position": _do_joint_position,
            "joint_max_velocity": _do_joint_max_velocity,
            "signal": _do_signal,
            "key": _do_key,
            "event": _do_event,
        }
    )

    def _add_cameras(self, background: bool | None):
        """The configuration's cameras' renderer (twin.sim.camera), or None: it sees each frame
        after every sink, and the twin hands its pictures to the sinks (_send_image)."""
        if not self.config.cameras:
            return None
        from twin.sim.camera import CameraRenderer

        return CameraRenderer(self.config, self._send_image, background=background)

    def finish_pictures(self) -> None:
        """Hand the cameras' pictures still being drawn to the sinks now (close does it too): for a
        caller that closes its recorders before the twin."""
        if self._camera_renderer is not None:
            self._camera_renderer.flush()

    def close(self) -> None:
        """Hand on the pictures still being drawn and end the simulation."""
        if self._camera_renderer is not None:
            self._camera_renderer.close()
        self._world.close()


def _number(value: Any, what: str) -> float:
    number = finite_number(value)
    if number is None:
        raise ConfigError(f"{what} {value!r:.40} is invalid; expected a finite number")
    return number


def _replaced(values: tuple, i: int, value) -> tuple:
    return values[:i] + (value,) + values[i + 1 :]
