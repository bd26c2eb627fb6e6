"""The teleop terminal screen (curses): the twin's state, the last keys, the events and the key
help.

status_lines() is the screen's text (plain strings); CursesScreen draws it and reads keys. It reads
the session it is given (a teleop.session.Session) without importing it: the session drives the
screen. The terminal runs in raw mode so Ctrl-C and Ctrl-D arrive as keys and end the session
cleanly.
"""

from __future__ import annotations

import contextlib
import curses
import math
from typing import Any, Self

from twin.model.keymaps import help_lines
from twin.model.types import NO_BODY

_CURSES_NAMES = {
    curses.KEY_UP: "up",
    curses.KEY_DOWN: "down",
    curses.KEY_LEFT: "left",
    curses.KEY_RIGHT: "right",
    curses.KEY_HOME: "home",
    curses.KEY_END: "end",
    curses.KEY_PPAGE: "pageup",
    curses.KEY_NPAGE: "pagedown",
    curses.KEY_IC: "insert",
    curses.KEY_DC: "delete",
    curses.KEY_BACKSPACE: "backspace",
    curses.KEY_ENTER: "enter",
    27: "esc",
    3: "ctrl-c",
    4: "ctrl-d",
    9: "tab",
    10: "enter",
    13: "enter",
    32: "space",
    127: "backspace",
    **{curses.KEY_F0 + i: f"f{i}" for i in range(1, 13)},
}
SHOWN_KEYS = 16


def key_name(code: int) -> str | None:
    """The key name of a curses getch() code; None for codes no key map can bind (mouse, resize)."""
    if code in _CURSES_NAMES:
        return _CURSES_NAMES[code]
    if 33 <= code <= 126:
        return chr(code)
    return None


def _body(session: Any, index: int) -> str:
    return "-" if index == NO_BODY else session.twin.config.objects[index].name


def _yaw_deg(q: tuple[float, ...]) -> float:
    x, y, z, w = q
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _joint_line(label: str, q: tuple[float, ...]) -> str:
    return (
        f"{label} (deg, m)  shoulder {math.degrees(q[0]):+7.2f}  elbow {math.degrees(q[1]):+7.2f}  "
        f"Z {q[2]:.4f}  wrist {math.degrees(q[3]):+7.2f}"
    )


def status_lines(session: Any) -> list[str]:
    """The screen's text, top to bottom."""
    twin = session.twin
    f = twin.frame
    q, target = f.joint_q, f.joint_target
    pad = f.pad_pose
    heading = math.degrees(q[0] + q[1] + q[3])
    rec = f"  recording {session.record_path}" if session.record_path else ""
    quit_text = ", ".join(
        {"esc": "Esc", "ctrl-c": "Ctrl-C", "ctrl-d": "Ctrl-D"}.get(k, k) for k in session.quit
    )
    held = _body(session, f.held_body)
    lines = [
        f"twin teleop  robot {twin.profile.name}  t {twin.t_s:9.3f} s  step {twin.step_index}{rec}",
        _joint_line("joints ", q),
        _joint_line("targets", target),
        f"pad      x {pad[0]:+.4f}  y {pad[1]:+.4f}  z {pad[2]:+.4f} m  heading {heading:+.1f} deg",
        f"suction  {'ON ' if f.suction_on else 'off'}  sensed: "
        f"{_body(session, f.sensed_body)}  held: {held}"
        + (f"   HOLDING {held}" if f.held_body != NO_BODY else ""),
    ]
    for obj, pose in zip(twin.config.objects, f.object_poses, strict=True):
        lines.append(
            f"{obj.name:<8} x {pose[0]:+.4f}  y {pose[1]:+.4f}  z {pose[2]:+.4f} m  "
            f"yaw {_yaw_deg(pose[3:]):+.1f} deg"
        )
    shown = [p.key if p.known else f"{p.key}(unknown)" for p in session.presses[-SHOWN_KEYS:]]
    lines.append("last keys " + (" ".join(shown) if shown else "(none yet)"))
    for ev in session.log.recent:
        lines.append(f"  t {ev.t_ns * 1e-9:8.3f} s  {ev.kind:<12} {ev.message}")
    lines.append("")
    lines.append(f"keys ({len(twin.config.keymap)}), quit: {quit_text}")
    lines.extend(help_lines(twin.config.keymap))
    return lines


class CursesScreen:
    """The curses terminal: raw mode, no echo, arrow keys decoded; a key source and a display."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self.window = None

    def __enter__(self) -> Self:
        self.window = curses.initscr()
        try:
            curses.set_escdelay(25)  # Esc alone must not wait a second for a sequence
            curses.noecho()
            curses.raw()
            self.window.keypad(True)
            with contextlib.suppress(curses.error):  # a terminal without cursor control
                curses.curs_set(0)
        except BaseException:
            curses.endwin()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.window.keypad(False)
        curses.noraw()
        curses.echo()
        curses.endwin()

    def read(self, timeout_s: float) -> list[str]:
        """Keys typed since the last read, waiting up to timeout_s for the first."""
        self.window.timeout(max(0, round(timeout_s * 1000)))
        keys = []
        code = self.window.getch()
        while code != -1:
            name = key_name(code)
            if name is not None:
                keys.append(name)
            self.window.timeout(0)
            code = self.window.getch()
        return keys

    def draw(self) -> None:
        height, width = self.window.getmaxyx()
        self.window.erase()
        lines = status_lines(self.session)
        if len(lines) > height:  # a small terminal: keep the state, cut the help
            lines = lines[: height - 1] + ["(enlarge the terminal for the full key help)"]
        for row, text in enumerate(lines[:height]):
            # the bottom-right cell raises in curses; the text is there
            with contextlib.suppress(curses.error):
                self.window.addnstr(row, 0, text, width - 1)
        self.window.refresh()
