"""Distributions a sweep draws a key's value from: `uniform(a,b)`, `normal(mu,sigma)`,
`choice(v1,v2,...)` or a constant, parsed from the text a user writes after `--vary KEY=`."""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from twin.model.errors import ConfigError
from twin.model.json_values import MAX_DEPTH, nesting_depth

_CALL = re.compile(r"^\s*([a-z_]+)\s*\((.*)\)\s*$", re.DOTALL)
MAX_CHOICES = 1000
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1  # a Parquet int64 column, as every integer a value meets
# normal(mu,sigma) needs mu +- 40 sigma finite: numpy's standard normal stays within +-13.8
NORMAL_REACH = 40
FINITE = "a finite number (at most +-1.8e308)"
WHOLE = "a whole number -2**63..2**63-1 (int64)"


class BadValue(ValueError):
    """A number a value cannot carry (an integer outside int64, NaN, an infinity, 1e400); the
    message names the number and what was expected."""


@dataclass(frozen=True)
class Dist:
    """One distribution: kind "uniform" (args a, b), "normal" (mu, sigma), "choice" (the values) or
    "constant" (one value). `text` is how the user wrote it (kept for the results and the
    summary)."""

    kind: str
    args: tuple
    text: str

    def sample(self, rng: np.random.Generator) -> object:
        """One value drawn with rng (a generator made for this scenario and key alone)."""
        if self.kind == "uniform":
            return float(rng.uniform(self.args[0], self.args[1]))
        if self.kind == "normal":
            return float(rng.normal(self.args[0], self.args[1]))
        if self.kind == "choice":
            return self.args[int(rng.integers(len(self.args)))]
        return self.args[0]

    def candidates(self) -> tuple:
        """Values that show whether a key accepts this distribution before anything runs: both ends
        of a uniform, the mean of a normal, every choice, the constant."""
        if self.kind == "normal":
            return (self.args[0],)
        return self.args

    @property
    def real(self) -> bool:
        """True when the draws are real numbers (uniform, normal), not given values."""
        return self.kind in ("uniform", "normal")


def parse_dist(text: str, key: str = "") -> Dist:
    """A distribution from its text; ConfigError (one line, naming the key and what was
    expected)."""
    shown = _short(text, 80) if isinstance(text, str) else text
    where = f"--vary {key}={shown}" if key else f"distribution {shown!r}"
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(
            f"{where} is invalid; expected uniform(a,b), normal(mu,sigma), "
            f"choice(v1,v2,...) or a value"
        )
    m = _CALL.match(text)
    if m is None:
        return Dist("constant", (_value(text.strip(), where),), text.strip())
    kind, inner = m.group(1), m.group(2)
    values = tuple(_value(v, where) for v in _split(inner, where))
    if kind in ("uniform", "normal"):
        if len(values) != 2 or not all(_is_number(v) for v in values):
            raise ConfigError(f"{where} is invalid; expected {kind}(two finite numbers)")
        a, b = (float(v) for v in values)
        if kind == "uniform" and not a < b:
            raise ConfigError(f"{where} is invalid; expected uniform(a,b) with a < b")
        if kind == "uniform" and not math.isfinite(b - a):  # numpy draws a + (b - a) * u
            raise ConfigError(
                f"{where} is invalid; expected uniform(a,b) with b - a finite (at most +-1.8e308)"
            )
        if kind == "normal" and not b > 0:
            raise ConfigError(f"{where} is invalid; expected normal(mu,sigma) with sigma > 0")
        # numpy draws mu + sigma * z
        if kind == "normal" and not math.isfinite(abs(a) + NORMAL_REACH * b):
            raise ConfigError(
                f"{where} is invalid; expected normal(mu,sigma) with mu +- {NORMAL_REACH}*sigma "
                "finite (at most +-1.8e308)"
            )
        return Dist(kind, (a, b), text.strip())
    if kind == "choice":
        if not values or len(values) > MAX_CHOICES:
            raise ConfigError(
                f"{where} is invalid; expected choice(v1,v2,...) with 1 to {MAX_CHOICES} values"
            )
        return Dist("choice", values, text.strip())
    raise ConfigError(f"{where}: unknown distribution {kind!r}; expected uniform, normal or choice")


def _split(inner: str, where: str) -> list[str]:
    """The arguments between the parentheses, split at commas outside double quotes."""
    parts, current, quoted = [], [], False
    for ch in inner:
        if ch == '"':
            quoted = not quoted
        if ch == "," and not quoted:
            parts.append("".join(current))
            current = []
        else:
            current.append(ch)
    if quoted:
        raise ConfigError(f"{where} is invalid: an unclosed quote")
    parts.append("".join(current))
    if len(parts) == 1 and not parts[0].strip():
        return []
    if any(not p.strip() for p in parts):
        raise ConfigError(f"{where} is invalid: an empty argument")
    return [p.strip() for p in parts]


def _value(text: str, where: str) -> object:
    """A value as JSON when it parses (numbers, true/false, "quoted text"), else the bare text; an
    integer outside int64 or a number that is not finite is refused."""
    try:
        value = read_value(text)
    except BadValue as err:
        raise ConfigError(f"{where} is invalid: {err}") from None
    if isinstance(value, (list, dict)) or value is None:
        raise ConfigError(f"{where} is invalid: {text} is not a number, true/false or text")
    return value


def read_value(text: str) -> object:
    """text as JSON when it parses (numbers, true/false, "text", null, lists, tables), else the text
    itself. BadValue for a number that cannot be carried, anywhere in it: an integer outside int64,
    NaN, an infinity, a float beyond +-1.8e308 (1e400), or a bare nan or inf that is not JSON."""
    too_deep = False
    try:
        value = json.loads(text, parse_int=_int64, parse_float=_finite, parse_constant=_not_finite)
    except BadValue:
        raise
    except RecursionError:  # json's parser recursed past Python's limit
        too_deep = True
    except ValueError:
        pass
    else:
        if nesting_depth(value) <= MAX_DEPTH:
            return value
        too_deep = True
    if too_deep:
        raise BadValue(
            f"{_short(text)}: arrays or tables nest more than {MAX_DEPTH} levels deep; "
            f"expected at most {MAX_DEPTH}"
        )
    try:
        number = float(text)
    except ValueError:
        return text
    if not math.isfinite(number):  # nan, inf, -Infinity, +1e400: meant as numbers, never as text
        _finite(text.strip())
    return text


def _int64(text: str) -> int:
    """A JSON integer; BadValue outside int64 (checked before converting: no 4300-digit int())."""
    value = int(text) if len(text.lstrip("-")) <= 19 else None
    if value is None or not INT64_MIN <= value <= INT64_MAX:
        raise BadValue(f"{_short(text)} is outside int64; expected {WHOLE}")
    return value


def _finite(text: str) -> float:
    """A JSON real number; BadValue when it is not finite (1e400 reads as inf)."""
    value = float(text)
    if not math.isfinite(value):
        _not_finite(text)
    return value


def _not_finite(text: str) -> NoReturn:
    raise BadValue(f"{_short(text)} is not a finite number; expected {FINITE}")


def _short(text: str, most: int = 40) -> str:
    """A value as written, cut to fit one line of an error."""
    return text if len(text) <= most else f"{text[: most - 16]}...({len(text)} characters)"


def _is_number(v: object) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float))
