"""Key maps for teleoperation: the built-in map of each profile, a user's --keymap file, key names.

A key map is plain data carried in TwinConfig.keymap (so a recording replays its keys the same
way): key name -> list of actions, in SI units (rad for revolute joints, m for Z):
  ["jog", joint, delta]               the joint's target moves by delta
  ["jog_keep_heading", joint, delta]  shoulder/elbow jog; the wrist turns back so the pad keeps
                                      its heading
  ["target", joint, value|"min"|"max"|"down"|"up"]
                                      ("down"/"up": the scene's Z values, profile.z_down/z_up)
  ["position", joint, value]          set at once (a jump, like sim.setJointPosition)
  ["add", joint, delta, "target"|"position"]  the map's own variable for the joint (from 0, as the
                                      reports' scripts keep one) moves by delta; the joint is
                                      sent there
  ["diff", joint, a, b]               the joint's variable becomes a's minus b's; its target goes
                                      there
  ["signal", name, value]             an integer signal
  ["suction", 0|1]                    the profile's suction signal
Joints are named by role (shoulder, elbow, z, wrist) or by the profile's own joint names.

Key names: a single printable character (case matters: "A" is Shift+a), or one of NAMED_KEYS.
Quit keys are never bound: Esc, Ctrl-C and Ctrl-D always end a session; `q` ends it too unless the
map binds `q` (seed000 uses q for the elbow).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Protocol

from twin.model.errors import ConfigError, UnknownName
from twin.model.json_values import load_json_text, load_toml_text
from twin.model.profiles import ROLES, RobotProfile

NAMED_KEYS = (
    "up",
    "down",
    "left",
    "right",
    "space",
    "enter",
    "tab",
    "backspace",
    "delete",
    "insert",
    "home",
    "end",
    "pageup",
    "pagedown",
    *(f"f{i}" for i in range(1, 13)),
)
ALWAYS_QUIT = ("esc", "ctrl-c", "ctrl-d")
WAIT = "wait"  # in a --keys script: no key for one interval
OPS = ("jog", "jog_keep_heading", "target", "position", "add", "diff", "signal", "suction")
_ARITY = {
    "jog": 3,
    "jog_keep_heading": 3,
    "target": 3,
    "position": 3,
    "add": 4,
    "diff": 4,
    "signal": 3,
    "suction": 2,
}
HOW = ("target", "position")


def _deg(d: float) -> float:
    return math.radians(d)


def _jog(role: str, delta: float) -> list:
    return ["jog", role, delta]


def _jog_kh(role: str, delta: float) -> list:
    return ["jog_keep_heading", role, delta]


# seed000, as report 000's Lua does it: its variables angle1, angle2, d start at 0; a/d: angle1 -/+1
# deg, q/e: angle2 -/+1 deg, each set at once (sim.setJointPosition); 8: d = d - 0.05, joint3 set to
# d and suction on (its first press sets -0.05, wherever Z is); 5: joint3 set to 0.084 (the lower
# stop; d unchanged); s: suction off.
SEED000 = {
    "a": [["add", "shoulder", -_deg(1), "position"]],
    "d": [["add", "shoulder", _deg(1), "position"]],
    "q": [["add", "elbow", -_deg(1), "position"]],
    "e": [["add", "elbow", _deg(1), "position"]],
    "8": [["add", "z", -0.05, "position"], ["suction", 1]],
    "5": [["position", "z", 0.084]],
    "s": [["suction", 0]],
}

# seed001, as report 001's Lua does it: CoppeliaSim keys 2009/2010 (left/right) deg1 +/-1 and
# deg3 = deg2 - deg1; 2007/2008 (up/down) deg2 +/-1 and deg3 = deg1 - deg2 (so the pad does not keep
# its heading); targets, not jumps; 3: Z -0.055 (down) + suction on, 4: Z 0 (up), 5: suction off.
SEED001 = {
    "left": [["add", "shoulder", _deg(1), "target"], ["diff", "wrist", "elbow", "shoulder"]],
    "right": [["add", "shoulder", -_deg(1), "target"], ["diff", "wrist", "elbow", "shoulder"]],
    "up": [["add", "elbow", _deg(1), "target"], ["diff", "wrist", "shoulder", "elbow"]],
    "down": [["add", "elbow", -_deg(1), "target"], ["diff", "wrist", "shoulder", "elbow"]],
    "3": [["target", "z", -0.055], ["suction", 1]],
    "4": [["target", "z", 0.0]],
    "5": [["suction", 0]],
}

# mtb (and seed002, seed003): coarse 5 deg and fine 1 deg (Shift) steps, the pad keeps its heading.
MTB = {
    "a": [_jog_kh("shoulder", -_deg(5))],
    "d": [_jog_kh("shoulder", _deg(5))],
    "A": [_jog_kh("shoulder", -_deg(1))],
    "D": [_jog_kh("shoulder", _deg(1))],
    "j": [_jog_kh("elbow", -_deg(5))],
    "l": [_jog_kh("elbow", _deg(5))],
    "J": [_jog_kh("elbow", -_deg(1))],
    "L": [_jog_kh("elbow", _deg(1))],
    "u": [_jog("wrist", -_deg(5))],
    "o": [_jog("wrist", _deg(5))],
    "k": [["target", "z", "down"]],
    "i": [["target", "z", "up"]],
    "g": [["suction", 1]],
    "r": [["suction", 0]],
}

BUILTIN: dict[str, dict] = {
    "mtb": MTB,
    "seed000": SEED000,
    "seed001": SEED001,
    "seed002": MTB,
    "seed003": MTB,
}


def builtin_keymap(profile_name: str) -> dict:
    """A copy of the built-in map of a profile (the mtb map for a user's profile)."""
    return json.loads(json.dumps(BUILTIN.get(profile_name, MTB)))


def is_key_name(name: object) -> bool:
    return isinstance(name, str) and (
        (len(name) == 1 and 33 <= ord(name) <= 126) or name in NAMED_KEYS
    )


def quit_keys(keymap: dict) -> tuple[str, ...]:
    """The keys that end a session with this map: q unless the map binds it, Esc, Ctrl-C, Ctrl-D."""
    return (() if "q" in keymap else ("q",)) + ALWAYS_QUIT


MAX_REPEAT = 100_000  # presses per token: ample for any session, and no runaway list


def parse_keys(text: str) -> list[str]:
    """A --keys script: whitespace-separated tokens, each a key name or `wait` (no key for one
    interval), optionally `*N` to repeat it N times ("d*30 e 8 wait*4 s"). Quit keys end the session
    there."""
    keys: list[str] = []
    for token in text.split():
        name, count = token, 1
        head, star, tail = token.rpartition("*")
        if star and head and tail.isdigit():
            name, count = head, int(tail)
            if not 1 <= count <= MAX_REPEAT:
                raise ConfigError(
                    f"--keys token {token!r}: repeat count {count} is invalid; "
                    f"expected *1 to *{MAX_REPEAT}"
                )
        if not (is_key_name(name) or name in ALWAYS_QUIT or name == WAIT):
            raise ConfigError(
                f"--keys token {token!r} is not a key; expected a single character or one of "
                f"{', '.join(NAMED_KEYS[:8])}, ..., esc, or wait, optionally followed by *N"
            )
        keys.extend([name] * count)
    return keys


def _value(src: str, key: str, action: list, raw: object, joint: int) -> float:
    """A joint delta/target: a number in SI units, or "Ndeg" for a revolute joint."""
    if isinstance(raw, str) and raw.endswith("deg") and joint != ROLES.index("z"):
        try:
            raw = math.radians(float(raw[:-3]))
        except ValueError:
            pass
    try:
        finite = not isinstance(raw, bool) and isinstance(raw, (int, float)) and math.isfinite(raw)
    except OverflowError:  # a JSON integer too large for a float
        finite = False
    if not finite:
        unit = "metres" if joint == ROLES.index("z") else 'radians or a string like "5deg"'
        raise _bad(src, key, action, f"value {raw!r} is not a finite number; expected {unit}")
    return float(raw)


def _bad(src: str, key: str, action: object, what: str) -> ConfigError:
    return ConfigError(f"key map {src}: key {key!r} action {json.dumps(action)}: {what}")


def _action(src: str, key: str, action: object, profile: RobotProfile) -> list:
    if not isinstance(action, list) or not action or action[0] not in OPS:
        raise _bad(src, key, action, f"expected a list [op, ...] with op one of {', '.join(OPS)}")
    op = action[0]
    if len(action) != _ARITY[op]:
        shapes = {
            "jog": "[op, joint, delta]",
            "target": '[op, joint, value|"min"|"max"|"down"|"up"]',
            "position": "[op, joint, value]",
            "add": '[op, joint, delta, "target"|"position"]',
            "diff": "[op, joint, a, b]",
            "signal": "[op, name, integer]",
            "suction": "[op, 0|1]",
        }
        raise _bad(
            src, key, action, f"has {len(action)} items; expected {shapes.get(op, shapes['jog'])}"
        )
    if op == "suction":
        if action[1] not in (0, 1) or isinstance(action[1], bool):
            raise _bad(src, key, action, f"suction value {action[1]!r} is invalid; expected 0 or 1")
        return [op, int(action[1])]
    if op == "signal":
        name, value = action[1], action[2]
        if not isinstance(name, str) or not name:
            raise _bad(
                src, key, action, f"signal name {name!r} is invalid; expected a non-empty string"
            )
        if isinstance(value, bool) or not isinstance(value, int):
            raise _bad(src, key, action, f"signal value {value!r} is invalid; expected an integer")
        return [op, name, value]
    joint_name = action[1]
    joint = _joint(src, key, action, joint_name, profile)
    if op == "jog_keep_heading" and ROLES[joint] not in ("shoulder", "elbow"):
        raise _bad(
            src, key, action, f"keeping the heading needs the shoulder or elbow, not {joint_name!r}"
        )
    if op == "target" and (
        action[2] in ("min", "max") or action[2] in ("down", "up") and ROLES[joint] == "z"
    ):
        return [op, ROLES[joint], action[2]]
    if op == "diff":
        return [
            op,
            ROLES[joint],
            *(ROLES[_joint(src, key, action, name, profile)] for name in action[2:4]),
        ]
    if op == "add":
        if action[3] not in HOW:
            raise _bad(
                src, key, action, f"how {action[3]!r} is invalid; expected one of {', '.join(HOW)}"
            )
        return [op, ROLES[joint], _value(src, key, action, action[2], joint), action[3]]
    return [op, ROLES[joint], _value(src, key, action, action[2], joint)]


def _joint(src: str, key: str, action: list, name: object, profile: RobotProfile) -> int:
    """The role index of a joint an action names (by role or by the profile's own name)."""
    try:
        if isinstance(name, str):
            return profile.joint_index(name)
    except UnknownName:
        pass
    raise _bad(
        src,
        key,
        action,
        f"unknown joint {name!r}; expected one of {', '.join(ROLES)} "
        f"or {', '.join(profile.joint_names)}",
    )


def validate_keymap(keymap: object, profile: RobotProfile, src: str = "(built-in)") -> dict:
    """Check every key and action; the normalized map (sorted keys, SI floats, role names)."""
    if not isinstance(keymap, dict) or not keymap:
        raise ConfigError(f"key map {src}: expected a non-empty table of key = [[action], ...]")
    out = {}
    for key in sorted(keymap):
        if not is_key_name(key):
            raise ConfigError(
                f"key map {src}: key {key!r} is not a key name; expected a single printable "
                f"character or one of {', '.join(NAMED_KEYS)}"
            )
        actions = keymap[key]
        if not isinstance(actions, list) or not actions:
            raise ConfigError(
                f"key map {src}: key {key!r}: expected a non-empty list of actions, got "
                f"{json.dumps(actions)}"
            )
        if all(not isinstance(a, list) for a in actions):
            actions = [actions]  # a single action written without the outer list
        out[key] = [_action(src, key, a, profile) for a in actions]
    return out


def load_keymap(path: str | Path, profile: RobotProfile) -> dict:
    """A user's key map file (.toml or .json): a table `keys` of key = list of actions, and
    optionally `extends = "mtb"|"seed000"|...` to start from a built-in map."""
    p = Path(path)
    src = repr(str(p))
    if p.suffix not in (".toml", ".json"):
        raise ConfigError(f"key map {src}: unknown file type {p.suffix!r}; expected .toml or .json")
    if not p.is_file():
        raise ConfigError(f"key map {src} does not exist")
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(
            f"key map {src} cannot be read: {(str(err).splitlines() or [type(err).__name__])[0]}"
        ) from err
    # malformed or nested too deep: one line, never a RecursionError
    what = f"key map {src} cannot be read"
    data = load_toml_text(text, what) if p.suffix == ".toml" else load_json_text(text, what)
    if not isinstance(data, dict) or not isinstance(data.get("keys"), dict):
        raise ConfigError(f"key map {src}: expected a table `keys` (key = list of actions)")
    unknown = sorted(str(k) for k in set(data) - {"keys", "extends"})
    if unknown:
        raise ConfigError(
            f"key map {src}: unknown entries {unknown}; expected `keys` and optionally `extends`"
        )
    base: dict = {}
    if "extends" in data:
        if not isinstance(data["extends"], str) or data["extends"] not in BUILTIN:
            raise ConfigError(
                f"key map {src}: extends {data['extends']!r} is unknown; expected one of "
                f"{', '.join(BUILTIN)}"
            )
        base = builtin_keymap(data["extends"])
    return validate_keymap({**base, **data["keys"]}, profile, src)


def keymap_for(profile: RobotProfile, path: str | Path | None = None) -> dict:
    """The map a session uses: the user's file if given, else the profile's built-in map."""
    if path:
        return load_keymap(path, profile)
    return validate_keymap(builtin_keymap(profile.name), profile)


class KeyHands(Protocol):
    """What a key's actions may do to a robot (the twin hands KeyPlayer one of these)."""

    def joint(self, name: str | int) -> int: ...  # a joint by role, profile name or index
    def target(self, joint: int) -> float: ...  # its motor target now
    def limits(self, joint: int) -> tuple[float, float]: ...
    def drive(self, joint: int, q: float) -> None: ...  # a new motor target
    def place(self, joint: int, q: float) -> None: ...  # set at once, like sim.setJointPosition
    def signal(self, name: str, value) -> None: ...


class KeyPlayer:
    """Plays a key map's actions (the list in the module doc) on a robot, in order. Keeps the map's
    own joint variables ("add", "diff"), from 0 as the reports' scripts keep them."""

    def __init__(self, keymap: dict, profile: RobotProfile) -> None:
        self.keymap, self.profile = keymap, profile
        self._values: dict[int, float] = {}

    def press(self, key: str, hands: KeyHands) -> bool:
        """Play key's actions; False if the map does not bind it (nothing done)."""
        actions = self.keymap.get(key)
        if actions is None:
            return False
        for action in actions:
            self._play(key, action, hands)
        return True

    def _play(self, key: str, action: list, hands: KeyHands) -> None:
        op, values = action[0], self._values
        if op in ("jog", "jog_keep_heading"):
            j = hands.joint(action[1])
            before = hands.target(j)
            hands.drive(j, before + float(action[2]))
            # turn back by what the joint moved
            if op == "jog_keep_heading" and hands.target(j) != before:
                wrist = _WRIST
                hands.drive(wrist, hands.target(wrist) - (hands.target(j) - before))
        elif op == "target":
            j = hands.joint(action[1])
            lo, hi = hands.limits(j)
            named = {"min": lo, "max": hi, "down": self.profile.z_down(), "up": self.profile.z_up()}
            hands.drive(j, float(named.get(action[2], action[2])))
        elif op == "position":
            hands.place(hands.joint(action[1]), float(action[2]))
        elif op == "add":
            j = hands.joint(action[1])
            values[j] = values.get(j, 0.0) + float(action[2])
            (hands.place if action[3] == "position" else hands.drive)(j, values[j])
        elif op == "diff":
            j, a, b = (hands.joint(name) for name in action[1:4])
            values[j] = values.get(a, 0.0) - values.get(b, 0.0)
            hands.drive(j, values[j])
        elif op == "signal":
            hands.signal(action[1], action[2])
        elif op == "suction":
            hands.signal(self.profile.suction_signals[0], int(action[1]))
        else:
            raise ConfigError(f"key {key!r}: unknown action {op!r}")


_WRIST = ROLES.index("wrist")  # joints in role order: the twin's joint indices


def describe_action(action: list) -> str:
    """Short words for one action, for the help on screen."""
    op = action[0]
    if op == "suction":
        return "suction on" if action[1] else "suction off"
    if op == "signal":
        return f"signal {action[1]}={action[2]}"
    joint, value = action[1], action[2]
    if op == "diff":
        return f"{joint} target = {value} - {action[3]}"
    if op == "position":
        return (
            f"set Z to {value:.3f} m"
            if joint == "z"
            else f"set {joint} to {math.degrees(value):+g} deg"
        )
    if op == "add":
        how = "set" if action[3] == "position" else "target"
        step = f"{value * 100:+g} cm" if joint == "z" else f"{math.degrees(value):+.4g} deg"
        return f"{joint} {step} ({how}; the map's own count from 0)"
    if op == "target":
        if joint == "z" and value in ("down", "up"):
            return "lower Z (down)" if value == "down" else "raise Z (up)"
        if value in ("min", "max"):
            return f"{joint} to its {value}"
        return f"Z to {value:.3f} m" if joint == "z" else f"{joint} to {math.degrees(value):+g} deg"
    if joint == "z":
        return f"{'lower' if value > 0 else 'raise'} Z {abs(value) * 100:g} cm"
    text = f"{joint} {math.degrees(value):+.4g} deg"
    return text + " (pad keeps heading)" if op == "jog_keep_heading" else text


def help_lines(keymap: dict) -> list[str]:
    """One line per key: `key  what it does`, grouped by joint (shoulder, elbow, Z, wrist, then
    the rest)."""

    def order(key: str) -> tuple:
        first = keymap[key][0]
        joint = (
            first[1]
            if first[0] in ("jog", "jog_keep_heading", "target", "position", "add", "diff")
            else ""
        )
        return (
            ROLES.index(joint) if joint in ROLES else len(ROLES),
            key.lower(),
            key != key.lower(),
        )

    return [
        f"{key:>5}  " + " + ".join(describe_action(a) for a in keymap[key])
        for key in sorted(keymap, key=order)
    ]
