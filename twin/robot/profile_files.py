"""Robot profiles by name or from a user's profile file (.toml/.json naming a URDF): the one place
that reads profile files, so the profile model does not depend on URDF parsing."""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import replace
from pathlib import Path

from twin.errors import ConfigError
from twin.model.profiles import DEFAULT_SUCTION_SIGNAL, PROFILES, ROLES, RobotProfile
from twin.robot.urdf import profile_from_urdf


def get_profile(name_or_path: str) -> RobotProfile:
    """A built-in profile by name, or a user's profile file (.toml/.json) naming a URDF."""
    if name_or_path in PROFILES:
        return PROFILES[name_or_path]
    path = Path(name_or_path)
    if path.suffix in (".toml", ".json"):
        return load_profile_file(path)
    raise ConfigError(
        f"unknown robot {name_or_path!r}; expected one of {', '.join(PROFILES)} or a profile file (.toml/.json)"
    )


def _length_m(value: object, path: Path) -> float:
    try:
        length = float(value)
    except (TypeError, ValueError):
        length = math.nan
    if not 0.0 < length < 1.0:
        raise ConfigError(f"robot profile {str(path)!r}: pad_length_m {value!r} is invalid; expected metres, 0..1")
    return length


def load_profile_file(path: Path) -> RobotProfile:
    """Read a user's profile file: `urdf`, `joints` (role -> URDF joint name), `pad_link`, optional
    `name`, `suction_signal`, `pad_length_m`. Geometry and limits come from the URDF itself."""
    if not path.is_file():
        raise ConfigError(f"robot profile file {str(path)!r} does not exist")
    try:
        text = path.read_text()
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (ValueError, OSError) as err:
        raise ConfigError(f"cannot read robot profile {str(path)!r}: {err}") from err
    for key in ("urdf", "joints", "pad_link"):
        if key not in data:
            raise ConfigError(f"robot profile {str(path)!r} lacks {key!r}; expected urdf, joints, pad_link")
    joints = data["joints"]
    missing = [r for r in ROLES if r not in joints]
    if missing:
        raise ConfigError(f"robot profile {str(path)!r}: joints lacks {missing}; expected {list(ROLES)}")
    urdf_path = (path.parent / data["urdf"]).resolve()
    profile = profile_from_urdf(
        urdf_path,
        name=data.get("name", path.stem),
        joint_names=tuple(joints[r] for r in ROLES),
        pad_link=data["pad_link"],
        pad_length_m=_length_m(data.get("pad_length_m", 0.012), path),
    )
    signal = data.get("suction_signal")
    if signal:
        profile = replace(profile, suction_signals=(signal, DEFAULT_SUCTION_SIGNAL))
    return profile
