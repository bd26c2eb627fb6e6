"""Keys typed into the PyBullet window (--gui) under Xvfb, injected with the X server's XTEST
extension: each becomes a recorded key Command, Shift gives capitals, Esc (which closes PyBullet's
window) ends the session cleanly, and the recording replays exactly."""

import ctypes
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from twin.cli import main
from twin.record.mcap.reader import load
from twin.record.outputs import partial_path


def _libs():
    try:
        return ctypes.CDLL("libX11.so.6"), ctypes.CDLL("libXtst.so.6")
    except OSError:
        return None


LIBS = _libs()
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        shutil.which("Xvfb") is None or LIBS is None,
        reason="needs Xvfb and libXtst (tools/setup_test_system.sh)",
    ),
]


class XKeyboard:
    """A client of an X display that waits for a window and types into it through XTEST."""

    def __init__(self, display: str) -> None:
        x11, xtst = LIBS
        x11.XOpenDisplay.restype = ctypes.c_void_p
        x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
        x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
        x11.XStringToKeysym.restype = ctypes.c_ulong
        x11.XStringToKeysym.argtypes = [ctypes.c_char_p]
        x11.XKeysymToKeycode.restype = ctypes.c_ubyte
        x11.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
        x11.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
        x11.XDefaultRootWindow.restype = ctypes.c_ulong
        x11.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
        window_list = ctypes.POINTER(ctypes.POINTER(ctypes.c_ulong))
        x11.XQueryTree.argtypes = [
            ctypes.c_void_p,
            ctypes.c_ulong,
            ctypes.POINTER(ctypes.c_ulong),
            ctypes.POINTER(ctypes.c_ulong),
            window_list,
            ctypes.POINTER(ctypes.c_uint),
        ]
        x11.XFree.argtypes = [ctypes.c_void_p]
        xtst.XTestFakeKeyEvent.argtypes = [
            ctypes.c_void_p,
            ctypes.c_uint,
            ctypes.c_int,
            ctypes.c_ulong,
        ]
        xtst.XTestFakeMotionEvent.argtypes = [
            ctypes.c_void_p,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_ulong,
        ]
        self.x11, self.xtst = x11, xtst
        self.display = x11.XOpenDisplay(display.encode())
        assert self.display, f"cannot open X display {display}"

    def windows(self) -> int:
        root, parent = ctypes.c_ulong(), ctypes.c_ulong()
        children, count = ctypes.POINTER(ctypes.c_ulong)(), ctypes.c_uint()
        self.x11.XQueryTree(
            self.display,
            self.x11.XDefaultRootWindow(self.display),
            ctypes.byref(root),
            ctypes.byref(parent),
            ctypes.byref(children),
            ctypes.byref(count),
        )
        if children:
            self.x11.XFree(children)
        return count.value

    def point_at(self, x: int, y: int) -> None:
        self.xtst.XTestFakeMotionEvent(self.display, -1, x, y, 0)
        self.x11.XSync(self.display, 0)

    def _code(self, keysym: str) -> int:
        return self.x11.XKeysymToKeycode(self.display, self.x11.XStringToKeysym(keysym.encode()))

    def tap(self, keysym: str, *, shift: bool = False, hold_s: float = 0.05) -> None:
        codes = ([self._code("Shift_L")] if shift else []) + [self._code(keysym)]
        for code in codes:
            self.xtst.XTestFakeKeyEvent(self.display, code, 1, 0)
        self.x11.XSync(self.display, 0)
        time.sleep(hold_s)
        for code in reversed(codes):
            self.xtst.XTestFakeKeyEvent(self.display, code, 0, 0)
        self.x11.XSync(self.display, 0)

    def close(self) -> None:
        self.x11.XCloseDisplay(self.display)


_first_size: dict[Path, int] = {}


def _grown(path: Path) -> bool:
    """True once the recording has grown past its first size (frames are being flushed)."""
    if not path.exists():
        return False
    size = path.stat().st_size
    return size > _first_size.setdefault(path, size)


@pytest.fixture
def xvfb():
    number = 300 + os.getpid() % 300
    while Path(f"/tmp/.X11-unix/X{number}").exists() or Path(f"/tmp/.X{number}-lock").exists():
        number += 1
    display = f":{number}"
    server = subprocess.Popen(
        ["Xvfb", display, "-screen", "0", "1024x768x24", "-nolisten", "tcp", "-noreset"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while not Path(f"/tmp/.X11-unix/X{number}").exists():
        assert time.monotonic() < deadline and server.poll() is None, "Xvfb did not start"
        time.sleep(0.05)
    yield display
    server.terminate()
    server.wait(timeout=10)


def test_keys_typed_into_the_window_are_recorded_and_replay_exactly(xvfb, tmp_path, capsys):
    record = tmp_path / "window.mcap"
    env = {**os.environ, "DISPLAY": xvfb, "HOME": str(tmp_path)}
    twin = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "teleop", "--gui", "--record", str(record)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    keyboard = XKeyboard(xvfb)
    try:
        deadline = time.monotonic() + 30
        # the window is up and the session is stepping (written to NAME.partial until it is
        # finalized)
        while keyboard.windows() == 0 or not _grown(partial_path(record)):
            assert time.monotonic() < deadline and twin.poll() is None, (
                "no PyBullet window or no steps"
            )
            time.sleep(0.05)
        keyboard.point_at(300, 300)  # no window manager: keys go to the window under the pointer
        # distinct keys in key-code order: even if some wait in PyBullet's queue, their order is
        # kept
        for keysym, shift in (("a", True), ("k", False), ("z", False), ("Left", False)):
            keyboard.tap(keysym, shift=shift, hold_s=0.3 if shift else 0.1)
            time.sleep(0.4)
        keyboard.tap("Escape")
        out, err = twin.communicate(timeout=30)
    finally:
        keyboard.close()
        if twin.poll() is None:
            twin.kill()
            twin.wait(timeout=10)
    assert twin.returncode == 0, err[-2000:]
    summary = next(line for line in out.splitlines() if line.startswith("teleop (gui)"))
    assert summary.startswith("teleop (gui) robot mtb: 4 key presses (2 not in the key map)"), (
        summary
    )
    # whoever saw Esc first
    assert summary.endswith(("ended by esc", "ended by window closed")), summary
    rec = load(record)
    assert rec.finalized and rec.run["params"]["mode"] == "gui"
    assert [c.args["key"] for c in rec.commands] == ["A", "k", "z", "left"]
    assert [e.data["key"] for e in rec.events if e.kind == "key_unknown"] == ["z", "left"]
    assert main(["replay", str(record)]) == 0
    assert capsys.readouterr().out.startswith("MATCH")


WINDOW_SHOT = """
import json, sys, time
from PIL import ImageGrab
from twin.model.config import TwinConfig
from twin.sim.world import World
world = World(TwinConfig(), gui=True)
time.sleep(1.5)  # the window draws in its own thread
ImageGrab.grab(xdisplay=sys.argv[1]).save(sys.argv[2])
print("camera=" + json.dumps(world.window_camera()), flush=True)
world.close()
"""


def test_the_window_opens_on_the_arm_with_the_debug_panels_hidden(xvfb, tmp_path):
    import json

    import numpy as np
    from PIL import Image

    shot = tmp_path / "window.png"
    done = subprocess.run(
        [sys.executable, "-c", WINDOW_SHOT, xvfb, str(shot)],
        check=False,
        capture_output=True,
        text=True,
        env={**os.environ, "DISPLAY": xvfb},
        timeout=60,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    camera = json.loads(
        next(line for line in done.stdout.splitlines() if line.startswith("camera="))[7:]
    )
    from twin.model.profiles import PROFILES

    reach_m = PROFILES["mtb"].link1_m + PROFILES["mtb"].link2_m
    assert reach_m < camera["distance_m"] < 2.5 * reach_m  # PyBullet's own default looks from 10 m
    assert camera["pitch_deg"] < -20
    rgb = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    arm = (r > 180) & (g < 150) & (b > 15) & (b < 100)  # the links' orange, not the floor's ochre
    # 0.02 % on the default view
    assert arm.mean() > 0.003, f"the arm covers {arm.mean():.2%} of the window"
