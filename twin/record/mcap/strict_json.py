"""JSON read from a recording, as the standard defines it.

Python's json accepts NaN, Infinity and -Infinity, and overflows 1e999 to inf; none of these is
JSON, and a recording never holds them (the writer refuses or writes null), so a file that does is
damaged. Deep nesting (a RecursionError in json) is refused the same way: one ValueError.
"""

from __future__ import annotations

import json
import math


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not a JSON number")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(
            f"{text[:40]} overflows a float: a number in it is not finite (NaN or infinity)"
        )
    return value


# made once: json.loads with keyword arguments builds a decoder per call (a third of a message's
# cost)
_STRICT = json.JSONDecoder(parse_constant=_no_constant, parse_float=_finite)
_LENIENT = json.JSONDecoder()


def loads(text: str | bytes, *, constants: bool = False) -> object:
    """Parse JSON text; ValueError for malformed JSON, NaN/Infinity, overflowing numbers, deep
    nesting. constants: let NaN and infinities through, for a caller whose schema then names the
    field."""
    try:
        # as json.loads decodes bytes (a JSON object: UTF-8, at once)
        if isinstance(text, bytes | bytearray):
            plain = text[:1] == b"{" and text[1:2] != b"\x00"
            text = text.decode("utf-8" if plain else json.detect_encoding(text), "surrogatepass")
        if text.startswith("\ufeff"):
            raise ValueError("Unexpected UTF-8 BOM (decode using utf-8-sig)")
        return (_LENIENT if constants else _STRICT).decode(text)
    except RecursionError as err:
        raise ValueError("JSON nested too deeply") from err
