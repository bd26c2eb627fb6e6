"""Keyboard teleoperation: a session that turns key presses into Commands, in real or simulated
time.

Each press becomes twin.press_key(key), a Command stamped with the step it takes effect at, and the
key map in the twin's config interprets it, so `twin replay` re-executes a session exactly. The
real-time loop is a pacing loop around the twin (step up to wall-clock time, poll keys briefly);
wall-clock time never reaches a Frame or a Command. Scripted sessions (--keys) run in simulated
time, as fast as the twin steps (or paced to real time when a window shows them).
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from twin.model.config import TwinConfig, dt_ns_from_hz
from twin.model.errors import ConfigError
from twin.model.keymaps import WAIT, keymap_for, parse_keys, quit_keys
from twin.model.sink import Sink
from twin.model.types import Event
from twin.robot.profile_files import get_profile
from twin.sim.twin import Twin
from twin.sim.world import engine_versions
from twin.tasks.pick_place import POINT_B_M as PLACE_M  # where the seeds' loop places the box

POLL_S = 0.01  # how long one poll of the keyboard may block
CHUNK_S = 0.02  # at most this much simulated time between two polls of the keyboard
DRAW_PERIOD_S = 0.05
MAX_LAG_S = 0.25  # beyond this the twin stops catching up with wall time (slow machine): time slips
DEFAULT_KEY_INTERVAL_S = 0.5
SHOWN_EVENTS = (
    "attach",
    "release",
    "break",
    "suction_empty",
    "joint_limit",
    "key_unknown",
    "settle_timeout",
)


@dataclass(frozen=True)
class KeyPress:
    step: int
    key: str
    known: bool  # False: not in the key map, ignored (a key_unknown Event)


class EventLog(Sink):
    """A sink keeping the latest events worth showing on screen and counting every kind."""

    def __init__(self, size: int = 6) -> None:
        self.recent: deque[Event] = deque(maxlen=size)
        self.counts: dict[str, int] = {}

    def on_event(self, event: Event) -> None:
        self.counts[event.kind] = self.counts.get(event.kind, 0) + 1
        if event.kind in SHOWN_EVENTS:
            self.recent.append(event)


class KeySource(Protocol):
    def read(self, timeout_s: float) -> list[str]: ...


class Session:
    """One teleop session on a twin: key presses, the log the screen shows, and the pacing loops."""

    def __init__(
        self, twin: Twin, log: EventLog, *, mode: str = "scripted", record_path: str = ""
    ) -> None:
        self.twin = twin
        self.log = log
        self.mode = mode
        self.record_path = record_path
        self.quit = quit_keys(twin.config.keymap)
        self.presses: list[KeyPress] = []
        self.ended_by = ""

    def press(self, key: str) -> bool:
        """Apply one key now; False when it is a quit key (nothing is recorded for it)."""
        if key in self.quit:
            self.ended_by = key
            return False
        self.twin.press_key(key)
        self.presses.append(KeyPress(self.twin.step_index, key, key in self.twin.config.keymap))
        return True

    def run_scripted(
        self, keys: list[str], interval_s: float, *, pace: Callable[[], None] | None = None
    ) -> None:
        """Press each key (`wait`: none), then let interval_s of simulated time pass; a quit key
        ends it."""
        steps = round(interval_s * 1e9 / self.twin.config.dt_ns)
        for key in keys:
            if key != WAIT and not self.press(key):
                return
            if not self._advance(steps, pace):
                return
        self.ended_by = "end of --keys"

    def _advance(self, steps: int, pace: Callable[[], None] | None) -> bool:
        if pace is None:
            return self._step(steps)
        for _ in range(steps):
            if not self._step(1):
                return False
            pace()
        return True

    def _step(self, steps: int) -> bool:
        """Step the twin; False when the PyBullet window was closed (PyBullet closes it on Esc,
        too)."""
        try:
            self.twin.step(steps)
        except Exception:
            if self.twin.gui and not self.twin.window_open():
                self.ended_by = "window closed"
                return False
            raise
        return True

    def run_realtime(
        self,
        sources: list[KeySource],
        draw: Callable[[], None] | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """Step the twin up to wall-clock time, reading keys between steps, until a quit key or
        Ctrl-C."""
        dt_s = self.twin.config.dt_s
        max_lag_steps = max(1, round(MAX_LAG_S / dt_s))
        chunk_steps = max(1, round(CHUNK_S / dt_s))
        origin_s, origin_step = clock(), self.twin.step_index
        next_draw_s = origin_s
        try:
            while True:
                behind = origin_step + int((clock() - origin_s) / dt_s) - self.twin.step_index
                # wait for keys only when the twin is not behind
                for i, source in enumerate(sources):
                    for key in source.read(POLL_S if i == 0 and behind <= 0 else 0.0):
                        if not self.press(key):
                            return
                behind = origin_step + int((clock() - origin_s) / dt_s) - self.twin.step_index
                if behind > max_lag_steps:
                    origin_s += (behind - max_lag_steps) * dt_s
                    behind = max_lag_steps
                if behind > 0 and not self._step(min(behind, chunk_steps)):
                    return
                if draw is not None and clock() >= next_draw_s:
                    draw()
                    next_draw_s = clock() + DRAW_PERIOD_S
        except KeyboardInterrupt:
            self.ended_by = "ctrl-c"

    def real_time_pacer(self, clock: Callable[[], float] = time.monotonic) -> Callable[[], None]:
        """A pace() for run_scripted that sleeps so simulated time keeps up with wall time."""
        origin_s, origin_step = clock(), self.twin.step_index
        dt_s = self.twin.config.dt_s

        def pace() -> None:
            ahead_s = (self.twin.step_index - origin_step) * dt_s - (clock() - origin_s)
            if ahead_s > 0.002:
                time.sleep(ahead_s)

        return pace


class WindowKeys:
    """Keys typed into the PyBullet window; closing the window ends the session like Esc."""

    def __init__(self, twin: Twin) -> None:
        self.twin = twin

    def read(self, timeout_s: float) -> list[str]:
        if timeout_s > 0:
            time.sleep(timeout_s)
        if not self.twin.window_open():
            return ["esc"]
        return self.twin.window_keys()


@dataclass
class TeleopOptions:
    robot: str = "mtb"
    rate_hz: float = 240.0
    gui: bool = False
    keymap_path: str = ""
    keys: str | None = None
    key_interval_s: float = DEFAULT_KEY_INTERVAL_S
    record_path: str | None = None
    rrd_path: str | None = None
    record_rate: int = 1
    extra_sinks: list = field(default_factory=list)
    cameras: tuple = ()  # model.images.CameraSpec: rendered into the recordings


def teleop_config(options: TeleopOptions) -> TwinConfig:
    profile = get_profile(options.robot)
    return TwinConfig(
        profile=profile,
        dt_ns=dt_ns_from_hz(options.rate_hz),
        keymap=keymap_for(profile, options.keymap_path or None),
        cameras=tuple(options.cameras),
    )


def run_teleop(options: TeleopOptions) -> Session:
    """Validate everything, open the recording, run the session in the chosen mode, finalize."""
    config = teleop_config(options)
    keys = parse_keys(options.keys) if options.keys is not None else None
    interval = options.key_interval_s
    if not (math.isfinite(interval) and 0.0 < interval <= 60.0):
        raise ConfigError(
            f"--key-interval {interval} s is invalid; expected a number of seconds in (0, 60]"
        )
    if keys is None and not options.gui and not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise ConfigError(
            'the teleop screen needs a terminal; use --keys "..." for a scripted session'
        )
    mode = "scripted" if keys is not None else ("gui" if options.gui else "terminal")
    run = {
        "source": "teleop",
        "task": "",
        "params": {
            "mode": mode,
            "keys": options.keys or "",
            "key_interval_s": interval,
            "keymap_file": options.keymap_path,
        },
    }
    from twin.record import open_recorders  # only record/ touches mcap and rerun

    log = EventLog()
    with open_recorders(
        config,
        run,
        mcap_path=options.record_path,
        rrd_path=options.rrd_path,
        rate=options.record_rate,
        engine=engine_versions(),
    ) as sinks:
        twin = Twin(config, gui=options.gui, sinks=[log, *sinks, *options.extra_sinks])
        session = Session(twin, log, mode=mode, record_path=options.record_path or "")
        try:
            if keys is not None:
                session.run_scripted(
                    keys, interval, pace=session.real_time_pacer() if options.gui else None
                )
            else:
                _run_interactive(session, options.gui)
        finally:
            twin.close()
    return session


def _run_interactive(session: Session, gui: bool) -> None:
    from twin.teleop.screen import CursesScreen

    sources: list[KeySource] = []
    if sys.stdin.isatty() and sys.stdout.isatty():
        with CursesScreen(session) as screen:
            sources.append(screen)
            if gui:
                sources.append(WindowKeys(session.twin))
            session.run_realtime(sources, screen.draw)
    else:
        session.run_realtime([WindowKeys(session.twin)])


def summary_lines(session: Session) -> list[str]:
    """What the CLI prints when a session ends."""
    twin = session.twin
    f = twin.frame
    unknown = [p.key for p in session.presses if not p.known]
    lines = [
        (
            f"teleop ({session.mode}) robot {twin.profile.name}: {len(session.presses)} "
            f"key presses "
            f"({len(unknown)} not in the key map), {twin.step_index} steps, simulated "
            f"{twin.t_s:.3f} s; "
            f"ended by {session.ended_by or 'quit'}"
        ),
        "events: "
        + (", ".join(f"{k} {v}" for k, v in sorted(session.log.counts.items())) or "none"),
    ]
    for obj, pose in zip(twin.config.objects, f.object_poses, strict=True):
        off_mm = 1000.0 * math.hypot(pose[0] - PLACE_M[0], pose[1] - PLACE_M[1])
        lines.append(
            f"{obj.name} final pose: x {pose[0]:+.4f} y {pose[1]:+.4f} z {pose[2]:+.4f} m, "
            f"{off_mm:.1f} mm from the place point ({PLACE_M[0]:g}, {PLACE_M[1]:g}) in x and y"
        )
    if session.record_path:
        lines.append(f"recorded {session.record_path}")
    return lines
