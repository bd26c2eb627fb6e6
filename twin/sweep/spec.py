"""A sweep's definition (`SweepSpec`: task, robot, seed, scenarios, varied keys, task parameters),
read from and written to TOML (`recordings/sweeps/NAME.toml`, `DIR/sweep.toml`), and `prepare`,
which checks every key and distribution before anything runs."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from twin.model.config import TwinConfig, dt_ns_from_hz
from twin.model.errors import ConfigError
from twin.model.json_values import load_toml_text
from twin.robot.profile_files import get_profile
from twin.sweep.dists import INT64_MAX, INT64_MIN, Dist, parse_dist
from twin.sweep.keys import Key, check_dist, resolve_key
from twin.tasks import TaskFn, check_params, resolve

MAX_SCENARIOS = 10_000_000
MAX_SEED = 2**63 - 1
SPEC_FIELDS = (
    "task",
    "robot",
    "seed",
    "scenarios",
    "rate_hz",
    "timeout_s",
    "params",
    "vary",
    "tolerance",
)
# what a statistical golden allows by default (recordings/sweeps/README in the README's Sweeps)
TOLERANCES = {
    "placement_p50_mm": 0.5,
    "placement_p95_mm": 1.0,
    "placement_max_mm": 2.0,
    "placement_shift_mm": 0.5,  # a paired golden (NAME.results.parquet): twin.sweep.paired
}
PAIRED_RULES = ("significant", "strict")  # tolerance `paired`: a paired golden's verdict rule
# tolerance `success_drop_pct` (optional, no default): the drop in success rate, in percentage
# points, that a paired verdict should detect; a warning (twin.sweep.power) when it cannot


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs. `vary` keeps the user's order ((key, distribution text) pairs); `params`
    are task parameters held constant; `tolerance` is used by statistical goldens only."""

    task: str
    scenarios: int
    robot: str = "mtb"
    seed: int = 0
    vary: tuple[tuple[str, str], ...] = ()
    params: dict = field(default_factory=dict)
    rate_hz: float = 240.0
    timeout_s: float | None = None
    tolerance: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if (
            isinstance(self.scenarios, bool)
            or not isinstance(self.scenarios, int)
            or not 1 <= self.scenarios <= MAX_SCENARIOS
        ):
            raise ConfigError(
                f"scenarios {self.scenarios!r} is invalid; expected a whole number "
                f"1..{MAX_SCENARIOS}"
            )
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, int)
            or not 0 <= self.seed <= MAX_SEED
        ):
            raise ConfigError(f"seed {self.seed!r} is invalid; expected a whole number 0..2**63-1")
        names = [k for k, _ in self.vary]
        if len(set(names)) != len(names):
            raise ConfigError(
                f"--vary names a key twice: {min(k for k in names if names.count(k) > 1)!r}"
            )
        if self.timeout_s is not None and not (
            isinstance(self.timeout_s, (int, float))
            and math.isfinite(self.timeout_s)
            and self.timeout_s > 0
        ):
            raise ConfigError(
                f"timeout_s {self.timeout_s!r} is invalid; expected seconds of simulated time > 0"
            )
        for name, value in self.tolerance.items():
            if name == "paired":
                if value not in PAIRED_RULES:
                    raise ConfigError(
                        f"tolerance paired = {value!r:.60} is invalid; expected "
                        '"significant" or "strict"'
                    )
                continue
            if name == "success_drop_pct":
                if not _number(value) or not 0 < value <= 100:
                    raise ConfigError(
                        f"tolerance success_drop_pct = {value!r:.60} is invalid; expected the "
                        "drop in success rate that matters, in percentage points: a number "
                        "> 0 and <= 100"
                    )
                continue
            if name not in TOLERANCES or not _number(value) or value < 0:
                # a NaN tolerance would pass any move
                raise ConfigError(
                    f"tolerance {name} = {value!r:.60} is invalid; expected one of "
                    f"{', '.join(TOLERANCES)} = a finite number >= 0 (mm), "
                    'success_drop_pct = percentage points, or paired = "significant" or "strict"'
                )

    def tolerances(self) -> dict[str, float]:
        return {**TOLERANCES, **self.tolerance}

    def key(self) -> str:
        """A text that identifies the definition (workers cache what they prepared under it)."""
        return json.dumps(
            [
                self.task,
                self.robot,
                self.seed,
                self.vary,
                self.params,
                self.rate_hz,
                self.timeout_s,
            ],
            sort_keys=True,
        )


@dataclass(frozen=True)
class Prepared:
    """A checked definition: the task function, the base configuration, the keys with their
    distributions (in the definition's order)."""

    spec: SweepSpec
    fn: TaskFn
    config: TwinConfig
    keys: tuple[tuple[Key, Dist], ...]


def prepare(spec: SweepSpec) -> Prepared:
    """Resolve the task and robot and check every key, distribution and parameter: ConfigError
    (one line, exit 2) before any scenario runs."""
    fn = resolve(spec.task)
    config = TwinConfig(profile=get_profile(spec.robot), dt_ns=dt_ns_from_hz(spec.rate_hz))
    check_params(fn, spec.params, spec.task)
    keys = []
    for name, text in spec.vary:
        key = resolve_key(name, config, fn, spec.task)
        if key.part == "task" and key.field in spec.params:
            raise ConfigError(
                f"task parameter {key.field!r} is both --param and --vary {name}; expected one"
            )
        dist = parse_dist(text, name)
        check_dist(key, dist, config, fn)
        keys.append((key, dist))
    return Prepared(spec, fn, config, tuple(keys))


def _number(value: object) -> bool:
    """A finite int or float (not a bool)."""
    return (
        isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    )


def parse_vary(texts: list[str]) -> tuple[tuple[str, str], ...]:
    """--vary KEY=DIST options as (key, distribution text) pairs."""
    out = []
    for text in texts:
        key, sep, dist = text.partition("=")
        if not sep or not key.strip() or not dist.strip():
            raise ConfigError(
                f"--vary {text!r} is invalid; expected KEY=DIST, e.g. box.x_m=uniform(0.18,0.22)"
            )
        out.append((key.strip(), dist.strip()))
    return tuple(out)


def load_spec(path: str | Path) -> SweepSpec:
    """A sweep definition from TOML; a task file or robot profile file named in it is found
    relative to the definition's folder. ConfigError (exit 2) naming the file and the field."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise ConfigError(
            f"sweep definition {str(path)!r} cannot be read: {err.strerror or err}"
        ) from err
    except UnicodeDecodeError as err:
        raise ConfigError(f"sweep definition {str(path)!r} is not valid TOML: {err}") from err
    # also too deep: one line
    data = load_toml_text(text, f"sweep definition {str(path)!r} is not valid TOML")
    unknown = sorted(set(data) - set(SPEC_FIELDS))
    if unknown:
        raise ConfigError(
            f"sweep definition {str(path)!r} has unknown field {unknown[0]!r}; "
            f"expected {', '.join(SPEC_FIELDS)}"
        )
    for name, kind in (
        ("task", str),
        ("robot", str),
        ("params", dict),
        ("vary", dict),
        ("tolerance", dict),
    ):
        if name in data and not isinstance(data[name], kind):
            raise ConfigError(
                f"sweep definition {str(path)!r}: {name} must be a "
                f"{'string' if kind is str else 'table'}"
            )
    for name in ("rate_hz", "timeout_s"):
        if name in data and (
            isinstance(data[name], bool) or not isinstance(data[name], (int, float))
        ):
            raise ConfigError(
                f"sweep definition {str(path)!r}: {name} = {data[name]!r:.60} is invalid; "
                "expected a number"
            )
    for name, value in data.get("params", {}).items():
        bad = _not_json_like(value)
        if bad is not None:
            raise ConfigError(
                f"sweep definition {str(path)!r}: params.{name} holds {bad}; expected a finite "
                "number, an int64 whole number, true/false, text, or a list or table of them"
            )
    if "task" not in data or "scenarios" not in data:
        raise ConfigError(f"sweep definition {str(path)!r} needs task and scenarios")
    if not all(isinstance(v, str) for v in data.get("vary", {}).values()):
        raise ConfigError(
            f"sweep definition {str(path)!r}: each vary value must be a string such as "
            '"uniform(0.18, 0.22)"'
        )
    folder = path.parent
    try:
        return SweepSpec(
            task=_beside(data["task"], folder, ".py"),
            scenarios=data["scenarios"],
            robot=_beside(data.get("robot", "mtb"), folder, ".toml"),
            seed=data.get("seed", 0),
            vary=tuple(data.get("vary", {}).items()),
            params=dict(data.get("params", {})),
            rate_hz=float(data.get("rate_hz", 240.0)),
            timeout_s=data.get("timeout_s"),
            tolerance=dict(data.get("tolerance", {})),
        )
    except ConfigError as err:
        raise ConfigError(f"sweep definition {str(path)!r}: {err}") from err
    except (TypeError, ValueError) as err:
        raise ConfigError(f"sweep definition {str(path)!r} holds a bad value: {err}") from err


def _not_json_like(value: object) -> str | None:
    """None when value is what JSON holds (a task parameter, as --param gives), else the first part
    that is not, described: a TOML date or time, a NaN or an infinity."""
    if isinstance(value, (str, bool)):
        return None
    if isinstance(value, int):  # Python's TOML reader takes any size; results and tasks take int64
        return None if INT64_MIN <= value <= INT64_MAX else f"{str(value)[:60]} (beyond int64)"
    if isinstance(value, float):
        return None if math.isfinite(value) else f"{value!r}"
    if isinstance(value, list):
        return next((bad for v in value if (bad := _not_json_like(v)) is not None), None)
    if isinstance(value, dict):
        return next((bad for v in value.values() if (bad := _not_json_like(v)) is not None), None)
    shown = value.isoformat() if hasattr(value, "isoformat") else repr(value)
    return f"{shown:.60} (a TOML {type(value).__name__})"


def _beside(name: str, folder: Path, suffix: str) -> str:
    """A file named relative to the definition's folder, when it is one; a built-in name as it
    is."""
    if name.endswith(suffix) and not Path(name).is_absolute() and (folder / name).is_file():
        return str(folder / name)
    return name


def dump_spec(spec: SweepSpec) -> str:
    """The definition as TOML (the format load_spec reads), e.g. DIR/sweep.toml of a sweep's
    output."""
    lines = [
        f"task = {_toml(spec.task)}",
        f"robot = {_toml(spec.robot)}",
        f"seed = {spec.seed}",
        f"scenarios = {spec.scenarios}",
    ]
    if spec.rate_hz != 240.0:
        lines.append(f"rate_hz = {_toml(spec.rate_hz)}")
    if spec.timeout_s is not None:
        lines.append(f"timeout_s = {_toml(spec.timeout_s)}")
    for table, items in (
        ("params", spec.params.items()),
        ("vary", spec.vary),
        ("tolerance", spec.tolerance.items()),
    ):
        items = list(items)
        if items:
            lines += ["", f"[{table}]"] + [f"{_toml(k)} = {_toml(v)}" for k, v in items]
    return "\n".join(lines) + "\n"


def _toml(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    raise ConfigError(
        f"value {value!r:.60} cannot be written to a sweep definition; expected numbers, "
        "true/false, text or lists"
    )
