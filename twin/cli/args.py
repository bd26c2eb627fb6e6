"""Argument types shared by the `twin` subcommands: each refuses bad text with one clear line."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from twin.model.config import TwinConfig, dt_ns_from_hz
from twin.model.errors import ConfigError
from twin.model.images import CAMERAS, DEFAULT_RATE_HZ, DEFAULT_SIZE_PX, MAX_SIDE_PX, camera
from twin.robot.profile_files import get_profile
from twin.sweep.dists import INT64_MAX, BadValue, read_value


def add_twin_options(p: argparse.ArgumentParser, *, gui: bool = True) -> None:
    """--robot and --rate-hz (and --gui where a window makes sense): what builds the twin."""
    p.add_argument(
        "--robot", default="mtb", help="profile: mtb, seed000..seed003, or a profile file"
    )
    p.add_argument("--rate-hz", type=float, default=240.0, help="physics rate (default 240 Hz)")
    if gui:
        p.add_argument("--gui", action="store_true", help="open the PyBullet window")
    add_camera_options(p)


def twin_config(args: argparse.Namespace) -> TwinConfig:
    """The twin configuration the --robot, --rate-hz and camera options ask for."""
    return TwinConfig(
        profile=get_profile(args.robot),
        dt_ns=dt_ns_from_hz(args.rate_hz),
        cameras=camera_specs(args),
    )


def add_camera_options(p: argparse.ArgumentParser) -> None:
    """--camera NAME (repeatable), --camera-size WxH, --camera-hz HZ: cameras rendered into the
    recordings."""
    default_w, default_h = DEFAULT_SIZE_PX
    p.add_argument(
        "--camera",
        action="append",
        default=[],
        choices=sorted(CAMERAS),
        metavar="NAME",
        help=f"render this camera into the recording (repeatable): {', '.join(CAMERAS)}",
    )
    p.add_argument(
        "--camera-size",
        type=size_px,
        default=None,
        metavar="WxH",
        help=f"picture size in pixels (default {default_w}x{default_h})",
    )
    p.add_argument(
        "--camera-hz",
        type=float,
        default=None,
        metavar="HZ",
        help=f"pictures per second of simulated time (default {DEFAULT_RATE_HZ:g})",
    )


def camera_specs(args: argparse.Namespace) -> tuple:
    """The cameras the options ask for (none without --camera)."""
    names = getattr(args, "camera", None) or []
    size, rate = getattr(args, "camera_size", None), getattr(args, "camera_hz", None)
    if not names and (size is not None or rate is not None):
        raise ConfigError(
            "--camera-size and --camera-hz need a --camera NAME; expected e.g. --camera overhead"
        )
    if len(set(names)) != len(names):
        raise ConfigError(f"--camera {names} names a camera twice; expected each camera once")
    return tuple(
        camera(n, size or DEFAULT_SIZE_PX, DEFAULT_RATE_HZ if rate is None else rate) for n in names
    )


def size_px(text: str) -> tuple[int, int]:
    """An argparse type: WxH in pixels, each 16..4096."""
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h)) if sep else None
    except ValueError:
        size = None
    if size is None or not all(16 <= v <= MAX_SIDE_PX for v in size):
        raise argparse.ArgumentTypeError(
            f"--camera-size {text!r} is invalid; expected WxH, e.g. 320x240, "
            f"each 16..{MAX_SIDE_PX} pixels"
        )
    return size


def add_param_option(p: argparse.ArgumentParser) -> None:
    """--param NAME=VALUE (repeatable): a task parameter, checked against the task function's
    signature."""
    p.add_argument(
        "--param",
        action="append",
        type=param_pair,
        default=[],
        metavar="NAME=VALUE",
        help="a task parameter (repeatable); VALUE as JSON when it parses (1, 0.5, true, "
        '"text", [1, 2]), else a string; NaN, infinities (1e400, inf) and integers outside '
        "int64 are refused",
    )


def param_pair(text: str) -> tuple[str, object]:
    """An argparse type: NAME=VALUE, VALUE parsed as JSON when it parses (numbers, true/false, null,
    lists), else kept as a string; NaN, infinities (also a bare nan or inf) and integers outside
    int64 are refused, anywhere in the value."""
    name, sep, raw = text.partition("=")
    if not sep or not name.isidentifier():
        raise argparse.ArgumentTypeError(
            f"--param {text!r} is invalid; expected NAME=VALUE, NAME a Python identifier"
        )
    try:
        value = read_value(raw)
    except BadValue as err:
        raise argparse.ArgumentTypeError(
            f"--param {name}={_short(raw)} is invalid: {err}"
        ) from None
    return name, value


def _short(text: str) -> str:
    return text if len(text) <= 60 else f"{text[:40]}...({len(text)} characters)"


def params_dict(pairs: list[tuple[str, object]]) -> dict:
    """The --param pairs as a dict; a name given twice is an error."""
    out: dict = {}
    for name, value in pairs:
        if name in out:
            raise ConfigError(f"--param {name} is given twice; expected each parameter once")
        out[name] = value
    return out


def add_scene_options(p: argparse.ArgumentParser) -> None:
    """--scene FILE.toml and --set KEY=VALUE (repeatable): the scene and settings a run starts
    from, stored in its recording's configuration."""
    p.add_argument(
        "--scene",
        metavar="FILE.toml",
        help="the objects on the floor: one [[box]] table each (name, size_m, mass_kg, pos_m, "
        "yaw_rad, friction, rgba); default: one box named box at (0.2, 0.7)",
    )
    p.add_argument(
        "--set",
        action="append",
        type=set_pair,
        default=[],
        dest="settings",
        metavar="KEY=VALUE",
        help="one setting (repeatable), with the keys of `twin sweep --vary`: <object>.x_m, "
        "<object>.y_m, <object>.z_m, <object>.yaw_rad, <object>.mass_kg, <object>.friction, "
        "pad.<field>, robot.<field>, engine.<field>; applied after --scene",
    )


def set_pair(text: str) -> tuple[str, object, str]:
    """An argparse type: KEY=VALUE, VALUE read as --param's are; (key, value, raw text)."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(
            f"--set {_short(text)!r} is invalid; expected KEY=VALUE, e.g. box.x_m=0.21"
        )
    try:
        value = read_value(raw)
    except BadValue as err:
        raise argparse.ArgumentTypeError(f"--set {key}={_short(raw)} is invalid: {err}") from None
    return key, value, raw


def scene_config(config: TwinConfig, args: argparse.Namespace, fn, task: str) -> TwinConfig:
    """config with --scene's objects, then each --set applied (checked against the configuration's
    schema, as a recording's is); unchanged without them, so such a run records what it did."""
    from dataclasses import replace

    from twin.model.scene import read_scene
    from twin.sweep.keys import apply_values, resolve_key

    if getattr(args, "scene", None):
        config = replace(config, objects=read_scene(args.scene))
    seen: set[str] = set()
    for name, value, raw in getattr(args, "settings", []):
        if name in seen:
            raise ConfigError(f"--set {name} is given twice; expected each key once")
        seen.add(name)
        key = resolve_key(name, config, fn, task, option="--set")
        if key.part == "task":
            raise ConfigError(
                f"--set {name}: task parameters go in --param {key.field}=VALUE; expected a "
                "scene, pad, robot or engine key"
            )
        config = apply_values(config, {key: value}, where=f"--set {name}={_short(raw)}")
    return config


def whole_number(minimum: int = 1) -> Callable[[str], int]:
    """An argparse type: an integer >= minimum that fits int64."""

    def parse(text: str) -> int:
        try:
            # no int() of thousands of digits
            value = int(text) if len(text) <= 24 else INT64_MAX + 1
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{_short(text)!r} is not a whole number >= {minimum}")
        if value > INT64_MAX:
            raise argparse.ArgumentTypeError(
                f"{_short(text)!r} is not a whole number {minimum}..2**63-1 (int64)"
            )
        return value

    return parse


def seconds(name: str, *, allow_zero: bool) -> Callable[[str], float]:
    """An argparse type: a finite number of seconds of simulated time, > 0 (or >= 0 with
    allow_zero)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = -1.0
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(
                f"{name} {text!r} is invalid; expected seconds of simulated time "
                f"{'>=' if allow_zero else '>'} 0"
            )
        return value

    return parse


def port(*, allow_any: bool = False) -> Callable[[str], int]:
    """An argparse type: a TCP port 1..65535, or 0 (any free port) when allow_any."""
    lowest = 0 if allow_any else 1

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if not lowest <= value <= 65535:
            expected = "0..65535 (0: any free port)" if allow_any else "a whole number 1..65535"
            raise argparse.ArgumentTypeError(f"port {text!r} is invalid; expected {expected}")
        return value

    return parse


def add_executor_options(
    p: argparse.ArgumentParser, jobs_default: int = 1, jobs_help: str = ""
) -> None:
    """--jobs/-j, --executor and --scheduler, in one wording for every command that spreads runs
    over worker processes (check, sweep, search)."""
    p.add_argument(
        "--jobs",
        "-j",
        type=whole_number(1),
        default=jobs_default,
        metavar="N",
        help=f"worker processes ({jobs_help or f'default {jobs_default}'})",
    )
    p.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local: processes on this machine (default); dask: Dask's distributed scheduler",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="with --executor dask: a running cluster's scheduler, tcp://HOST:8786 or "
        "tls://HOST:8786 (certificates from Dask's configuration; default: a cluster of --jobs "
        "workers on 127.0.0.1 that only this run can reach, TLS with a certificate made for it)",
    )
