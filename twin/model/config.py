"""Everything needed to rebuild a twin: profile, scene, time step, engine and pad parameters.

Plain data that round-trips through JSON, so a recording's metadata alone rebuilds the run.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields, replace

from twin.model.errors import ConfigError
from twin.model.images import CameraSpec
from twin.model.json_values import MAX_DEPTH, all_finite, nesting_depth, shown
from twin.model.keymaps import validate_keymap
from twin.model.profiles import PROFILES, RobotProfile


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
    # PyBullet's default 1e-7 lets the solver stop early: a box at rest creeps 0.5 mm / 0.27 deg in
    # 40 s (the yaw creep of long pick-and-place runs); 1e-12 leaves 1.6 um / 0.004 deg
    solver_residual_threshold: float = 1e-12


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
    # rendered into every recording of the run (model/images.py)
    cameras: tuple[CameraSpec, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.dt_ns, int) or not 100_000 <= self.dt_ns <= 100_000_000:
            raise ConfigError(
                f"time step {self.dt_ns!r} ns is out of range; expected an integer 1e5..1e8 ns"
            )
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ConfigError(f"scene object names must be unique, got {names}")
        cameras = [c.name for c in self.cameras]
        if len(set(cameras)) != len(cameras):
            raise ConfigError(f"camera names must be unique, got {cameras}")
        for camera in self.cameras:
            check_camera_view(camera)

    @property
    def dt_s(self) -> float:
        return self.dt_ns * 1e-9

    def to_dict(self) -> dict:
        """As stored in a recording; without cameras the record has no `cameras` field (as before
        cameras)."""
        out = asdict(self)
        if not self.cameras:
            del out["cameras"]
        return out

    @staticmethod
    def from_dict(data: object) -> TwinConfig:
        """The configuration a recording stores, every field checked against CONFIG_SCHEMA first:
        ConfigError naming the field (e.g. `objects[0].size_m[1]`) and what it should be."""
        data = _record(data, CONFIG_SCHEMA, "")
        profile = RobotProfile.from_dict(data["profile"])
        if data["keymap"]:
            # checked; kept as recorded
            validate_keymap(data["keymap"], profile, "twin.config keymap")
        return TwinConfig(
            profile=profile,
            objects=tuple(SceneObject(**o) for o in data["objects"]),
            dt_ns=data["dt_ns"],
            engine=EngineParams(**data["engine"]),
            suction=SuctionParams(**data["suction"]),
            keymap=data["keymap"],
            cameras=tuple(CameraSpec(**c) for c in data["cameras"]),
        )


def scene_object(data: object, where: str) -> SceneObject:
    """A scene object from a JSON-like dict (a scene file's [[box]] table), every field checked
    against OBJECT_SCHEMA as a recording's are; missing fields take SceneObject's defaults."""
    return SceneObject(**_record(data, OBJECT_SCHEMA, where))


MIN_VIEW_M = 1e-6  # a camera's eye and target are at least this far apart
# its up direction leans at least this much (sine of the angle) off the view direction
MIN_UP_SINE = 1e-6


def check_camera_view(camera: CameraSpec) -> None:
    """ConfigError unless the camera looks somewhere (eye_m and target_m apart) with an up direction
    that is not zero nor along the view: the image's axes are made from these (images.optical_pose).
    Checked in the camera's own axes, which a pad mount turns as a whole."""
    forward = tuple(t - e for t, e in zip(camera.target_m, camera.eye_m, strict=True))
    distance = math.sqrt(sum(c * c for c in forward))
    where = f"camera {camera.name!r}"
    if not distance >= MIN_VIEW_M:
        raise ConfigError(
            f"{where}: eye_m {list(camera.eye_m)} and target_m {list(camera.target_m)} are "
            f"{distance:g} m apart; expected a target at least {MIN_VIEW_M:g} m from the eye"
        )
    length = math.sqrt(sum(c * c for c in camera.up))
    if not length > 0:
        raise ConfigError(
            f"{where}: up {list(camera.up)} is no direction; expected a vector that is not zero, "
            "e.g. [0, 1, 0]"
        )
    f = [c / distance for c in forward]
    u = [c / length for c in camera.up]
    sine = math.sqrt(
        (f[1] * u[2] - f[2] * u[1]) ** 2
        + (f[2] * u[0] - f[0] * u[2]) ** 2
        + (f[0] * u[1] - f[1] * u[0]) ** 2
    )
    if not sine >= MIN_UP_SINE:
        raise ConfigError(
            f"{where}: up {list(camera.up)} is along the view direction (target_m - eye_m = "
            f"{[round(c, 9) for c in forward]}); expected an up direction across it"
        )


# -- the schema of a stored configuration ----------------------------------------------------------
# Every field a recording's `twin.config` holds, with its type and the range twin can simulate. A
# field missing from a record takes its default (older recordings); an unknown field is an error.

MAX_OBJECTS = 100
MAX_TEXT = 4096  # characters in a name, path or description


@dataclass(frozen=True)
class Field:
    """One field: kind "int", "float", "bool", "str", "floats" (count numbers), "strs", "dict", a
    nested schema (dict) or a list of one (list[dict]); numbers in lo..hi (lo excluded if
    open_lo)."""

    kind: object
    lo: float = -math.inf
    hi: float = math.inf
    open_lo: bool = False
    count: int = 0  # floats/strs: exactly this many (0: one to 64)

    def expected(self) -> str:
        """What a value of this field must be, in words (for every kind: a nested schema and a list
        of them are a dict and a list, which are not hashable, so they are told apart first)."""
        kind = self.kind
        if isinstance(kind, dict):
            return "a JSON object"
        if isinstance(kind, list):
            return f"a list of at most {MAX_OBJECTS} JSON objects"
        if kind in ("int", "float", "floats"):
            what = {
                "int": "a whole number",
                "float": "a finite number",
                "floats": f"{self.count} finite numbers",
            }
            return f"{what[kind]} {'>' if self.open_lo else '>='} {self.lo:g} and <= {self.hi:g}"
        if kind == "float?":
            return f"null or a finite number >= {self.lo:g} and <= {self.hi:g}"
        words = {
            "bool": "true or false",
            "str": f"a string (up to {MAX_TEXT} characters)",
            "signs": f"{self.count} signs, each 1 or -1",
            "strs": f"{self.count or 'one to 64'} non-empty strings",
            "dict": f"a JSON object of finite values, nested at most {MAX_DEPTH} deep",
        }
        return (
            words.get(kind, f"a value of kind {kind!r}")
            if isinstance(kind, str)
            else f"a value of kind {kind!r}"
        )


def _f(
    lo: float, hi: float, *, open_lo: bool = False, count: int = 0, kind: str = "float"
) -> Field:
    return Field("floats" if count else kind, lo, hi, open_lo, count)


_POSITIVE_M = _f(0, 10, open_lo=True)
_ANGLE_LIMIT = _f(0, 4 * math.pi, open_lo=True)
PROFILE_SCHEMA = {
    "name": Field("str"),
    "link1_m": _POSITIVE_M,
    "link2_m": _POSITIVE_M,
    "joint_names": Field("strs", count=4),
    "suction_signals": Field("strs"),
    **dict.fromkeys(("shoulder_height_m", "elbow_height_m", "tip_z0_m"), _f(-10, 10)),
    "z_stroke_m": _POSITIVE_M,
    **dict.fromkeys(("shoulder_limit_rad", "elbow_limit_rad", "wrist_limit_rad"), _ANGLE_LIMIT),
    **dict.fromkeys(
        ("revolute_max_velocity_rad_s", "prismatic_max_velocity_m_s"), _f(0, 1e4, open_lo=True)
    ),
    **dict.fromkeys(("revolute_max_torque_nm", "prismatic_max_force_n"), _f(0, 1e9, open_lo=True)),
    "pad_length_m": _f(0, 1, open_lo=True),
    **dict.fromkeys(("urdf_path", "pad_link", "description"), Field("str")),
    "extra": Field("dict"),
    # the scene's own joint conventions (docs/seed-conventions.md)
    "shoulder_zero_rad": _f(-10, 10),
    "axis_signs": Field("signs", count=4),
    "revolute_cyclic": Field("bool"),
    "z_lower_m": _f(-10, 10),
    **dict.fromkeys(("z_down_m", "z_up_m"), Field("float?", -10, 10)),
}
OBJECT_SCHEMA = {
    "name": Field("str"),
    "size_m": _f(0, 100, open_lo=True, count=3),
    "mass_kg": _f(0, 1e6, open_lo=True),
    "pos_m": _f(-1e3, 1e3, count=3),
    "yaw_rad": _f(-1e3, 1e3),
    "friction": _f(0, 1e3),
    "rgba": _f(0, 1, count=4),
}
ENGINE_SCHEMA = {
    "num_solver_iterations": _f(1, 10_000, kind="int"),
    "gravity_m_s2": _f(-1e3, 1e3, count=3),
    "deterministic_overlapping_pairs": _f(0, 1, kind="int"),
    "position_gain": _f(0, 1e3),
    "velocity_gain": _f(0, 1e3),
    "solver_residual_threshold": _f(0, 1),
}
SUCTION_SCHEMA = {
    "sensor_offset_m": _f(0, 1),
    "sensor_range_m": _f(0, 1, open_lo=True),
    "infinite_strength": Field("bool"),
    "max_pull_force_n": _f(0, 1e9),
    "max_shear_force_n": _f(0, 1e9),
    "max_peel_torque_nm": _f(0, 1e9),
}
CAMERA_SCHEMA = {
    "name": Field("str"),
    **dict.fromkeys(("width_px", "height_px"), _f(16, 4096, kind="int")),
    "rate_hz": _f(0.1, 1000),
    "fov_deg": _f(1, 170),
    **dict.fromkeys(("near_m", "far_m"), _f(0, 1e3, open_lo=True)),
    "mount": Field("str"),
    **dict.fromkeys(("eye_m", "target_m", "up"), _f(-1e3, 1e3, count=3)),
    "format": Field("str"),
}
CONFIG_SCHEMA = {
    "profile": Field(PROFILE_SCHEMA),
    "objects": Field([OBJECT_SCHEMA]),
    "dt_ns": _f(100_000, 100_000_000, kind="int"),
    "engine": Field(ENGINE_SCHEMA),
    "suction": Field(SUCTION_SCHEMA),
    "keymap": Field("dict"),
    "cameras": Field([CAMERA_SCHEMA]),
}


def _defaults(cls: type) -> dict:
    return {f.name: f.default for f in fields(cls) if f.default is not MISSING}


# A missing field takes the dataclass's default; one without a default is required.
_DEFAULTS = {
    id(PROFILE_SCHEMA): _defaults(RobotProfile),
    id(OBJECT_SCHEMA): _defaults(SceneObject),
    id(ENGINE_SCHEMA): _defaults(EngineParams),
    id(SUCTION_SCHEMA): _defaults(SuctionParams),
    id(CAMERA_SCHEMA): _defaults(CameraSpec),
    id(CONFIG_SCHEMA): {"keymap": {}, "cameras": []},
}


def _bad(where: str, value: object, spec: Field) -> ConfigError:
    return ConfigError(
        f"twin.config field {where} = {shown(value)} is invalid; expected {spec.expected()}"
    )


def _record(value: object, schema: dict, where: str) -> dict:
    """A JSON object checked field by field against schema; missing fields with defaults are filled
    in."""
    if not isinstance(value, dict):
        raise ConfigError(
            f"twin.config {where or 'record'} = {shown(value)} is invalid; expected a JSON object"
        )
    unknown = sorted(str(k) for k in value if k not in schema)
    if unknown:
        raise ConfigError(
            f"twin.config {where or 'record'} has unknown field {unknown[0][:60]!r}; "
            f"expected only {', '.join(schema)}"
        )
    defaults = _DEFAULTS[id(schema)]
    out = {}
    for name, spec in schema.items():
        path = f"{where}.{name}" if where else name
        if name in value:
            out[name] = _field(value[name], spec, path)
        elif name in defaults:
            out[name] = defaults[name]
        else:
            raise ConfigError(f"twin.config field {path} is missing; expected {spec.expected()}")
    return out


def _field(value: object, spec: Field, where: str) -> object:
    kind = spec.kind
    if isinstance(kind, dict):
        return _record(value, kind, where)
    if isinstance(kind, list):
        if not isinstance(value, list) or len(value) > MAX_OBJECTS:
            raise _bad(where, value, spec)
        return [_record(item, kind[0], f"{where}[{i}]") for i, item in enumerate(value)]
    if kind in ("floats", "strs"):
        if not isinstance(value, list) or (
            len(value) != spec.count if spec.count else not 1 <= len(value) <= 64
        ):
            raise _bad(where, value, spec)
        one = replace(spec, kind="float" if kind == "floats" else "str")
        items = [_field(v, one, f"{where}[{i}]") for i, v in enumerate(value)]
        if kind == "strs" and not all(items):
            raise _bad(where, value, spec)
        return tuple(items)
    if kind == "signs":  # a list of +1 / -1
        if (
            not isinstance(value, list)
            or len(value) != spec.count
            or any(isinstance(v, bool) or v not in (1, -1) for v in value)
        ):
            raise _bad(where, value, spec)
        return tuple(int(v) for v in value)
    if kind == "float?":  # a number, or null
        return None if value is None else _field(value, replace(spec, kind="float"), where)
    if kind == "str":
        if not isinstance(value, str) or len(value) > MAX_TEXT:
            raise _bad(where, value, spec)
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise _bad(where, value, spec)
        return value
    if kind == "dict":
        if not isinstance(value, dict) or nesting_depth(value) > MAX_DEPTH or not all_finite(value):
            raise _bad(where, value, spec)
        return value
    if isinstance(value, bool) or not isinstance(value, int if kind == "int" else (int, float)):
        raise _bad(where, value, spec)
    try:
        number = float(value) if kind == "float" else value
        inside = (spec.lo < number if spec.open_lo else spec.lo <= number) and number <= spec.hi
    except OverflowError:
        number, inside = value, False
    if not inside:  # NaN and infinities fall outside every range
        raise _bad(where, value, spec)
    return number


def dt_ns_from_hz(rate_hz: float) -> int:
    """Whole-nanosecond time step for a physics rate; refuses non-positive or absurd rates."""
    if not math.isfinite(rate_hz) or not 10.0 <= rate_hz <= 10_000.0:
        raise ConfigError(f"physics rate {rate_hz} Hz is out of range; expected 10..10000 Hz")
    return round(1e9 / rate_hz)
