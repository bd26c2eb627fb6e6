"""JSON values as recordings hold them: finite numbers only (NaN and infinities are not JSON); and
reading the JSON and TOML files a user hands twin (profiles, key maps, sweep definitions and
summaries) as one-line ConfigErrors, never a traceback.

Nesting is bounded: a file twin reads may nest arrays and tables (objects) at most MAX_DEPTH deep
(twin's own files nest 4 deep at most). Deeper text is refused when it is read (the parsers recurse
once per level: 1000 levels is a RecursionError), so nothing after it recurses into a deep value.
The walks here use no recursion.
"""

from __future__ import annotations

import json
import math
import tomllib

from twin.model.errors import ConfigError

MAX_DEPTH = 64  # arrays and tables inside one another, in a JSON or TOML file twin reads


def all_finite(value: object) -> bool:
    """No NaN or infinity anywhere inside value (dicts and lists walked, without recursion)."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, float):
            if not math.isfinite(v):
                return False
        elif isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list | tuple):
            stack.extend(v)
    return True


def finite_number(value: object) -> float | None:
    """value as a float if it is a finite int or float (a bool is no number), else None."""
    try:
        ok = (
            not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
        )
    except OverflowError:  # an int too large for a float
        return None
    return float(value) if ok else None


def finite_or_null(value: object) -> object:
    """value with every NaN or infinity replaced by None (JSON null)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_null(v) for v in value]
    return value


def nesting_depth(value: object, limit: int = MAX_DEPTH) -> int:
    """How deep lists (tuples) and dicts nest in value (a number or string: 0; [] and {}: 1),
    counted level by level without recursion; counting stops past `limit` (then limit + 1)."""
    depth, level = 0, [value]
    while True:
        containers = [v for v in level if isinstance(v, dict | list | tuple)]
        if not containers:
            return depth
        depth += 1
        if depth > limit:
            return depth
        level = [item for c in containers for item in (c.values() if isinstance(c, dict) else c)]


def shown(value: object, width: int = 60, *, as_json: bool = False) -> str:
    """repr(value) (or its JSON) cut to `width` characters, for an error message: a value read from
    a file may nest as deep as its parser allowed, and printing it recurses again."""
    try:
        text = json.dumps(value) if as_json else repr(value)
    except RecursionError:
        return "(a value nested too deeply to show)"
    except (TypeError, ValueError):
        text = repr(value)
    return text[:width]


def event_data(kind: str, data: dict) -> dict:
    """Event data as plain JSON values with sorted keys, exactly what a recording will give back
    (a non-finite number is null)."""
    if not data:
        return {}

    def plain(value: object) -> object:
        tolist = getattr(value, "tolist", None)  # numpy scalars and arrays
        if callable(tolist):
            return tolist()
        raise TypeError(f"a value of type {type(value).__name__!r}")

    try:
        # NaN and infinities become null, as the recording writes them: memory and file agree
        return json.loads(
            json.dumps(data, sort_keys=True, default=plain), parse_constant=lambda _: None
        )
    except (TypeError, ValueError) as err:
        raise ConfigError(
            f"event {kind!r} data {sorted(data)} holds {err}, which is not JSON data; "
            "expected numbers, strings, booleans, None, lists and dicts"
        ) from err


def _too_deep(what: str, limit: int) -> ConfigError:
    return ConfigError(
        f"{what}: arrays or tables nest more than {limit} levels deep; twin reads at most {limit}"
    )


def _first_line(err: BaseException) -> str:
    lines = str(err).strip().splitlines()
    return lines[0] if lines else type(err).__name__


def load_json_text(text: str | bytes, what: str, *, max_depth: int = MAX_DEPTH) -> object:
    """JSON text as Python values (json.loads), or a one-line ConfigError `{what}: {why}` for
    malformed JSON, undecodable bytes, or nesting deeper than max_depth (also where json would
    recurse too deep). `what` names the file and says what went wrong, e.g. "key map 'k.json' cannot
    be read"."""
    try:
        value = json.loads(text)
    except RecursionError:
        raise _too_deep(what, max_depth) from None
    except ValueError as err:  # JSONDecodeError, UnicodeDecodeError
        raise ConfigError(f"{what}: {_first_line(err)}") from err
    if nesting_depth(value, max_depth) > max_depth:
        raise _too_deep(what, max_depth)
    return value


def load_toml_text(text: str, what: str, *, max_depth: int = MAX_DEPTH) -> dict:
    """TOML text as a dict (tomllib.loads), or a one-line ConfigError `{what}: {why}` for malformed
    TOML or nesting deeper than max_depth (also where tomllib would recurse too deep)."""
    try:
        value = tomllib.loads(text)
    except RecursionError:
        raise _too_deep(what, max_depth) from None
    except ValueError as err:  # TOMLDecodeError
        raise ConfigError(f"{what}: {_first_line(err)}") from err
    if nesting_depth(value, max_depth) > max_depth:
        raise _too_deep(what, max_depth)
    return value
