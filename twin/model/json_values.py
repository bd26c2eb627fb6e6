"""JSON values as recordings hold them: finite numbers only (NaN and infinities are not JSON)."""

from __future__ import annotations

import math


def all_finite(value: object) -> bool:
    """No NaN or infinity anywhere inside value (dicts and lists walked)."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(all_finite(v) for v in value.values())
    if isinstance(value, list | tuple):
        return all(all_finite(v) for v in value)
    return True


def finite_or_null(value: object) -> object:
    """value with every NaN or infinity replaced by None (JSON null)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_null(v) for v in value]
    return value
