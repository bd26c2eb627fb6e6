"""The keys `twin search` varies: `KEY=LOW..HIGH` ranges, each key's nominal value (the scene's,
the pad's, the robot's, or the task's default) and the precision its boundary is found to, all
checked before anything runs."""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from dataclasses import dataclass

from twin.model.errors import ConfigError
from twin.sweep.dists import Dist, parse_dist
from twin.sweep.keys import Key, check_dist, resolve_key
from twin.sweep.spec import Prepared, SweepSpec, prepare
from twin.tasks import task_params

_RANGE = re.compile(r"^\s*(\S+?)\s*\.\.\s*(\S+)\s*$")
DEFAULT_PRECISION = 0.01  # of a key's half-width: 7 bisection steps from a range end


@dataclass(frozen=True)
class Range:
    """One searched key: its range, nominal value and the precision its boundary is found to."""

    key: Key
    low: float
    high: float
    nominal: float
    precision: float

    @property
    def name(self) -> str:
        return self.key.name

    @property
    def half_width(self) -> float:
        return (self.high - self.low) / 2


def parse_range(name: str, text: str) -> tuple[float, float]:
    """LOW..HIGH (or uniform(LOW,HIGH), as a sweep writes it); ConfigError naming the text."""
    m = _RANGE.match(text)
    if m is not None:
        try:
            low, high = float(m.group(1)), float(m.group(2))
        except ValueError:
            low = high = math.nan
    elif text.strip().startswith("uniform("):
        dist = parse_dist(text, name)
        low, high = dist.args
    else:
        low = high = math.nan
    if not (
        math.isfinite(low) and math.isfinite(high) and low < high and math.isfinite(high - low)
    ):
        raise ConfigError(
            f"--vary {name}={text} is invalid; expected a range LOW..HIGH of finite numbers "
            "with LOW < HIGH, e.g. box.x_m=0.15..0.25"
        )
    return low, high


def prepare_search(
    spec: SweepSpec, precision: float = DEFAULT_PRECISION
) -> tuple[Prepared, tuple[Range, ...]]:
    """Check the task, the keys, their ranges (both ends valid for the key, the nominal inside) and
    the parameters, before anything runs: ConfigError, one line. spec.vary holds the range texts."""
    if not spec.vary:
        raise ConfigError("--vary KEY=LOW..HIGH is missing; expected at least one key to search")
    if not (math.isfinite(precision) and 0 < precision < 1):
        raise ConfigError(
            f"--precision {precision!r} is invalid; expected a fraction of the half-width, "
            "0 < p < 1"
        )
    prep = prepare(dataclasses.replace(spec, vary=()))  # the task, robot and parameters
    ranges = []
    for name, text in spec.vary:
        key = resolve_key(name, prep.config, prep.fn, spec.task)
        if key.part == "task" and key.field in spec.params:
            raise ConfigError(
                f"task parameter {key.field!r} is both --param and --vary {name}; expected one"
            )
        nominal = nominal_value(key, prep)
        low, high = parse_range(name, text)
        check_dist(key, Dist("uniform", (low, high), text), prep.config, prep.fn)  # both ends valid
        if not low <= nominal <= high:
            raise ConfigError(
                f"--vary {name}={text} is invalid: the nominal value {nominal!r} lies outside; "
                "expected a range that holds it"
            )
        ranges.append(Range(key, low, high, nominal, (high - low) / 2 * precision))
    return prep, tuple(ranges)


def nominal_value(key: Key, prep: Prepared) -> float:
    """The key's value in the unperturbed scene: the configuration's, or the task's default."""
    config = prep.config
    if key.part == "task":
        param = (task_params(prep.fn) or {}).get(key.field)
        value = None if param is None or param.default is inspect.Parameter.empty else param.default
    elif key.part == "object":
        obj = next(o for o in config.objects if o.name == key.owner)
        value = getattr(obj, key.field)
        value = value[key.index] if key.index is not None else value
    else:
        owner = {"pad": config.suction, "robot": config.profile, "engine": config.engine}[key.part]
        value = getattr(owner, key.field)
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or isinstance(value, int)
        and key.part != "object"
    ):
        raise ConfigError(
            f"--vary {key.name}: its nominal value is {value!r}; search varies real-valued keys "
            "(a float default or field)"
        )
    return float(value)
