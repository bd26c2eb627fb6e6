"""The curses teleop screen driven in a real terminal (tmux): a pick and a place with the mtb map,
the screen read back at every stage, then quit and `twin replay` the recording with an exact
match."""

import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.teleop_plan import plan

from twin.cli import main
from twin.record.mcap.reader import load
from twin.tasks.pick_place import POINT_A_M, POINT_B_M

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        shutil.which("tmux") is None, reason="needs tmux (tools/setup_test_system.sh)"
    ),
]

NUMBER = r"([+-]?\d+\.\d+)"
JOINTS = re.compile(
    rf"shoulder +{NUMBER} +elbow +{NUMBER} +Z {NUMBER} +wrist +{NUMBER}$", re.MULTILINE
)
BOX = re.compile(rf"^box +x {NUMBER} +y {NUMBER} +z {NUMBER} m", re.MULTILINE)


class Terminal:
    """A detached tmux session on its own server socket, running one command."""

    def __init__(self, tmp_path: Path, command: str, width: int = 110, height: int = 40) -> None:
        self.socket = f"twin-teleop-{os.getpid()}-{tmp_path.name}"
        self.status = tmp_path / "exit_status"
        env = f"HOME={shlex.quote(str(tmp_path))} TERM=xterm-256color"
        shell = (
            f"cd {shlex.quote(os.getcwd())} && env {env} {command}; echo $? > "
            f"{shlex.quote(str(self.status))}"
        )
        self._tmux(
            "new-session",
            "-d",
            "-s",
            "teleop",
            "-x",
            str(width),
            "-y",
            str(height),
            "sh",
            "-c",
            shell,
        )

    def _tmux(self, *args: str) -> str:
        out = subprocess.run(
            ["tmux", "-L", self.socket, "-f", os.devnull, *args],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
        return out.stdout

    def send(self, *keys: str) -> None:
        self._tmux("send-keys", "-t", "teleop", *keys)

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "teleop")

    def wait_for(self, what: str, predicate, timeout_s: float = 20.0) -> str:
        deadline = time.monotonic() + timeout_s
        while True:
            text = self.screen()
            if predicate(text):
                return text
            if time.monotonic() > deadline:
                pytest.fail(f"the teleop screen never showed {what}; last screen:\n{text}")
            time.sleep(0.1)

    def wait_exit(self, timeout_s: float = 20.0) -> int:
        deadline = time.monotonic() + timeout_s
        while not (self.status.exists() and self.status.read_text().strip()):
            if time.monotonic() > deadline:
                pytest.fail(f"teleop did not exit; last screen:\n{self.screen()}")
            time.sleep(0.1)
        return int(self.status.read_text())

    def close(self) -> None:
        subprocess.run(
            ["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=10, check=False
        )


def _joints(text: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    actual, target = JOINTS.findall(text)[:2]
    return tuple(map(float, actual)), tuple(map(float, target))


def arrived(text: str) -> bool:
    """The joints line matches the targets line (the arm has stopped where the keys sent it)."""
    if len(JOINTS.findall(text)) < 2:
        return False
    actual, target = _joints(text)
    return all(
        abs(a - t) <= (2e-4 if i == 2 else 0.02)
        for i, (a, t) in enumerate(zip(actual, target, strict=True))
    )


def arrived_at(text: str, deg: tuple[int, int]) -> bool:
    """Arrived, with the shoulder and elbow targets at these whole degrees (every key sent has been
    read)."""
    return arrived(text) and all(
        abs(t - d) < 0.01 for t, d in zip(_joints(text)[1][:2], deg, strict=True)
    )


def box_xyz(text: str) -> tuple[float, float, float]:
    return tuple(map(float, BOX.search(text).groups()))


def mtb_keys(delta_deg: tuple[int, int]) -> list[str]:
    """The mtb map's keys for a shoulder/elbow move: 5-degree steps (a/d, j/l), then 1-degree steps
    (A/D, J/L)."""
    keys = []
    for delta, (minus, plus) in zip(delta_deg, (("a", "d"), ("j", "l")), strict=True):
        coarse, fine = divmod(abs(delta), 5)
        keys += [plus if delta > 0 else minus] * coarse + [
            (plus if delta > 0 else minus).upper()
        ] * fine
    return keys


@pytest.fixture
def terminal(tmp_path):
    made = []

    def start(command: str) -> Terminal:
        made.append(Terminal(tmp_path, command))
        return made[-1]

    yield start
    for t in made:
        t.close()


def test_curses_pick_and_place_then_replay_exactly(terminal, tmp_path, capsys):
    record = tmp_path / "teleop_mtb.mcap"
    cmd = (
        f"{shlex.quote(sys.executable)} -m twin.cli teleop --robot mtb --record "
        f"{shlex.quote(str(record))}"
    )
    term = terminal(cmd)
    text = term.wait_for("the start screen", lambda s: "last keys (none yet)" in s)
    assert (
        "quit: q, Esc, Ctrl-C, Ctrl-D" in text and "lower Z (down)" in text and "suction on" in text
    )
    assert math.dist(box_xyz(text)[:2], POINT_A_M) < 1e-3

    term.send("z")  # not in the mtb map: ignored, shown as such
    term.wait_for("the unknown key", lambda s: "z(unknown)" in s and "key_unknown" in s)

    pick, place, predicted_m = plan("mtb", keeps_heading=True)
    term.send(*mtb_keys(pick))
    text = term.wait_for("the arm over the box", lambda s: arrived_at(s, pick))
    assert _joints(text)[0][:2] == pytest.approx(pick, abs=0.02)
    term.send("k")  # lower Z to the scene's down
    term.wait_for("the pad down on the box", lambda s: arrived(s) and "Z 0.2000 " in s)
    term.send("g")  # suction on
    text = term.wait_for("the suction holding", lambda s: "HOLDING box" in s and "suction  ON" in s)
    assert "sensed: box  held: box" in text
    term.send("i")  # raise Z
    text = term.wait_for("the box lifted", lambda s: arrived(s) and "Z 0.0000 " in s)
    assert "held: box" in text and box_xyz(text)[2] > 0.2

    term.send(*mtb_keys((place[0] - pick[0], place[1] - pick[1])))
    text = term.wait_for("the arm over the place point", lambda s: arrived_at(s, place))
    assert _joints(text)[0][:2] == pytest.approx(place, abs=0.02)
    term.send("k")
    term.wait_for("the box lowered", lambda s: arrived(s) and "Z 0.2000 " in s)
    term.send("r")  # suction off
    term.wait_for("the box released", lambda s: "held: -" in s and "suction  off" in s)
    term.send("i")
    text = term.wait_for("the pad raised", lambda s: arrived(s) and "Z 0.0000 " in s)
    box = box_xyz(text)
    assert math.dist(box[:2], predicted_m) < 0.002 and math.dist(box[:2], POINT_B_M) < 0.005
    assert abs(box[2] - 0.025) < 1e-3

    term.send("q")
    assert term.wait_exit() == 0
    rec = load(record)
    assert rec.finalized and rec.run["params"]["mode"] == "terminal"
    keys = [c.args["key"] for c in rec.commands if c.kind == "key"]
    assert keys == [
        "z",
        *mtb_keys(pick),
        "k",
        "g",
        "i",
        *mtb_keys((place[0] - pick[0], place[1] - pick[1])),
        "k",
        "r",
        "i",
    ]
    assert [e.kind for e in rec.events if e.kind in ("attach", "release", "key_unknown")] == [
        "key_unknown",
        "attach",
        "release",
    ]
    assert main(["replay", str(record)]) == 0
    assert capsys.readouterr().out.startswith("MATCH")


def test_seed000_screen_ctrl_c_ends_and_keeps_the_recording(terminal, tmp_path):
    record = tmp_path / "teleop_seed000.mcap"
    cmd = (
        f"{shlex.quote(sys.executable)} -m twin.cli teleop --robot seed000 --record "
        f"{shlex.quote(str(record))}"
    )
    term = terminal(cmd)
    text = term.wait_for("the start screen", lambda s: "last keys (none yet)" in s)
    # q is the elbow here, not quit
    assert "quit: Esc, Ctrl-C, Ctrl-D" in text and "q  elbow -1 deg" in text
    term.send("q", "q", "e", "Up", "d")
    text = term.wait_for("the keys", lambda s: "last keys q q e up(unknown) d" in s and arrived(s))
    assert _joints(text)[1][:2] == (1.0, -1.0)
    term.send("C-c")
    assert term.wait_exit() == 0
    rec = load(record)
    assert rec.finalized and [c.args["key"] for c in rec.commands] == ["q", "q", "e", "up", "d"]
    assert main(["replay", str(record)]) == 0
