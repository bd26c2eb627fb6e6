"""JSON read from a recording, as the standard defines it.

Python's json accepts NaN, Infinity and -Infinity, and overflows 1e999 to inf; none of these is
JSON, and a recording never holds them (the writer refuses or writes null), so a file that does is
damaged. Deep nesting (a RecursionError in json) is refused the same way: one ValueError.
"""

from __future__ import annotations

import json

from twin.model.json_values import all_finite


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not a JSON number")


def loads(text: str | bytes, *, constants: bool = False) -> object:
    """Parse JSON text; ValueError for malformed JSON, NaN/Infinity, overflowing numbers, deep nesting.
    constants: let NaN and infinities through, for a caller whose schema then names the field."""
    try:
        value = json.loads(text) if constants else json.loads(text, parse_constant=_no_constant)
        if not constants and not all_finite(value):
            raise ValueError("a number in it is not finite (NaN or infinity)")
    except RecursionError as err:
        raise ValueError("JSON nested too deeply") from err
    return value

