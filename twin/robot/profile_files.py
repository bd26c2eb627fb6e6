"""Robot profiles by name or from a user's profile file (.toml/.json naming a URDF): the one place
that reads profile files, so the profile model does not depend on URDF parsing."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from twin.model.errors import ConfigError
from twin.model.json_values import load_json_text, load_toml_text
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
        f"unknown robot {name_or_path!r}; expected one of {', '.join(PROFILES)} or a "
        f"profile file (.toml/.json)"
    )


def _length_m(value: object, path: Path) -> float:
    try:
        length = float(value)
    except (TypeError, ValueError, OverflowError):
        length = math.nan
    if not 0.0 < length < 1.0:
        raise ConfigError(
            f"robot profile {str(path)!r}: pad_length_m {value!r} is invalid; expected metres, 0..1"
        )
    return length


def load_profile_file(path: Path) -> RobotProfile:
    """Read a user's profile file: `urdf`, `joints` (role -> URDF joint name), `pad_link`, optional
    `name`, `suction_signal`, `pad_length_m`. Geometry and limits come from the URDF itself."""
    if not path.is_file():
        raise ConfigError(f"robot profile file {str(path)!r} does not exist")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"cannot read robot profile {str(path)!r}: {err}") from err
    what = f"cannot read robot profile {str(path)!r}"  # malformed or nested too deep: one line
    data = load_toml_text(text, what) if path.suffix == ".toml" else load_json_text(text, what)
    if not isinstance(data, dict):
        raise ConfigError(
            f"robot profile {str(path)!r} is not a table; expected urdf, joints, pad_link"
        )
    for key in ("urdf", "joints", "pad_link"):
        if key not in data:
            raise ConfigError(
                f"robot profile {str(path)!r} lacks {key!r}; expected urdf, joints, pad_link"
            )
    for key in ("urdf", "pad_link", "name", "suction_signal"):
        if key in data and not isinstance(data[key], str):
            raise ConfigError(
                f"robot profile {str(path)!r}: {key} = {data[key]!r:.60} is invalid; "
                f"expected a string"
            )
    joints = data["joints"]
    if not isinstance(joints, dict):
        raise ConfigError(
            f"robot profile {str(path)!r}: joints = {joints!r:.60} is invalid; expected a table of "
            f"{', '.join(ROLES)} = URDF joint name"
        )
    missing = [r for r in ROLES if r not in joints]
    if missing:
        raise ConfigError(
            f"robot profile {str(path)!r}: joints lacks {missing}; expected {list(ROLES)}"
        )
    bad = next((r for r in ROLES if not isinstance(joints[r], str)), None)
    if bad is not None:
        raise ConfigError(
            f"robot profile {str(path)!r}: joints.{bad} = {joints[bad]!r:.60} is invalid; expected "
            "a URDF joint name"
        )
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
