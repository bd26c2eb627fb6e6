"""Everything needed to rebuild a twin: profile, scene, time step, engine and pad parameters.

Plain data that round-trips through JSON, so a recording's metadata alone rebuilds the run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from twin.errors import ConfigError
from twin.profiles import PROFILES, RobotProfile


@dataclass(frozen=True)
class SceneObject:
    """A box on the floor: size, mass and start pose (yaw about +z)."""

    name: str
    size_m: tuple[float, float, float] = (0.05, 0.05, 0.05)
    mass_kg: float = 0.1
    pos_m: tuple[float, float, float] = (0.2, 0.7, 0.025)
    yaw_rad: float = 0.0
    friction: float = 0.8
    rgba: tuple[float, float, float, float] = (0.2, 0.5, 0.9, 1.0)


@dataclass(frozen=True)
class EngineParams:
    """PyBullet engine settings, set explicitly after every (re)build."""

    num_solver_iterations: int = 50
    gravity_m_s2: tuple[float, float, float] = (0.0, 0.0, -9.81)
    deterministic_overlapping_pairs: int = 1
    position_gain: float = 0.3
    velocity_gain: float = 1.0


@dataclass(frozen=True)
class SuctionParams:
    """CoppeliaSim's stock suction pad: a ray sensor 13 mm below the pad root, 6 mm long."""

    sensor_offset_m: float = 0.013
    sensor_range_m: float = 0.006
    infinite_strength: bool = True
    max_pull_force_n: float = 3.0
    max_shear_force_n: float = 1.0
    max_peel_torque_nm: float = 0.1


DEFAULT_DT_NS = 4_166_667  # 1/240 s, rounded to whole nanoseconds


@dataclass(frozen=True)
class TwinConfig:
    profile: RobotProfile = PROFILES["mtb"]
    objects: tuple[SceneObject, ...] = (SceneObject("box"),)
    dt_ns: int = DEFAULT_DT_NS
    engine: EngineParams = field(default_factory=EngineParams)
    suction: SuctionParams = field(default_factory=SuctionParams)
    keymap: dict = field(default_factory=dict)  # key -> list of actions (teleop); empty: no keys

    def __post_init__(self) -> None:
        if not isinstance(self.dt_ns, int) or not 100_000 <= self.dt_ns <= 100_000_000:
            raise ConfigError(f"time step {self.dt_ns!r} ns is out of range; expected an integer 1e5..1e8 ns")
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ConfigError(f"scene object names must be unique, got {names}")

    @property
    def dt_s(self) -> float:
        return self.dt_ns * 1e-9

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(data: dict) -> TwinConfig:
        try:
            return TwinConfig(
                profile=RobotProfile.from_dict(data["profile"]),
                objects=tuple(
                    SceneObject(**{k: tuple(v) if isinstance(v, list) else v for k, v in o.items()})
                    for o in data["objects"]
                ),
                dt_ns=int(data["dt_ns"]),
                engine=EngineParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in data["engine"].items()}),
                suction=SuctionParams(**data["suction"]),
                keymap=dict(data.get("keymap", {})),
            )
        except (TypeError, KeyError) as err:
            raise ConfigError(f"malformed twin configuration: {err}") from err


def dt_ns_from_hz(rate_hz: float) -> int:
    """Whole-nanosecond time step for a physics rate; refuses non-positive or absurd rates."""
    if not math.isfinite(rate_hz) or not 10.0 <= rate_hz <= 10_000.0:
        raise ConfigError(f"physics rate {rate_hz} Hz is out of range; expected 10..10000 Hz")
    return round(1e9 / rate_hz)
