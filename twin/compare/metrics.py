"""Error metrics between two runs' columns, in physical units: (n, k, c) arrays -> (n, k) errors.

Revolute joint angles are wrapped to [-pi, pi]; orientations compare by the angle between
quaternions (q and -q are the same rotation); vectors by the norm of their difference.
"""

from __future__ import annotations

import math

import numpy as np

from twin.model.profiles import ROLES

REVOLUTE = np.array([role != "z" for role in ROLES])  # every joint but the prismatic Z


def abs_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a[..., 0] - b[..., 0])


def joint_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a[..., 0] - b[..., 0]
    # wrapped only beyond pi: (d + pi) rounds a difference below 4e-16 rad to 0
    wrapped = np.where(
        np.abs(d) <= math.pi, np.abs(d), np.abs((d + math.pi) % (2 * math.pi) - math.pi)
    )
    return np.where(REVOLUTE[: d.shape[1]], wrapped, np.abs(d))


def norm_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a - b, axis=-1)


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between unit quaternions along the last axis; q and -q are the same rotation."""
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    bs = b * sign
    return 2.0 * np.arctan2(np.linalg.norm(a - bs, axis=-1), np.linalg.norm(a + bs, axis=-1))


def discrete_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a[..., 0] != b[..., 0]).astype(np.float64)


def differs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bit-level inequality per (step, element), NaN equal to NaN."""
    ne = a != b
    if a.dtype.kind == "f":
        ne &= ~(np.isnan(a) & np.isnan(b))
    return ne.any(axis=-1)
