"""Comparing two joint logs sampled at their own times and clocks (a robot's ROS 2 bag beside a twin
run): align their clocks, interpolate the denser one linearly at the other's sample times, judge
each joint's position (and velocity and effort where both have them) against the tolerances.

Times of a log count from its first sample. The lag is how much later the second log (B) runs than
the first (A): B's sample at u seconds matches A at u - lag. Unless given, it is found: first the
first motion of each (a joint leaving its first value by MOTION_RAD), then the lag within two
sample intervals of that which fits the positions best (least squares, each joint's mean difference
taken out first, so that a constant offset on a joint does not move the lag).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from twin.compare.result import NotComparable
from twin.compare.tolerances import Tolerances
from twin.model.joint_log import JointLog

PAD_FRAME = "pad_tip"  # the pad tip's frame in /tf (record.mcap.scene_tf.PAD_TIP)
MOTION_RAD = 1e-3  # a joint has started moving once this far (rad or m) from its first value
QUANTITIES = (  # JointLog attribute, tolerance name, unit
    ("position_rad", "joints.position", "rad|m"),
    ("velocity_rad_s", "joints.velocity", "rad/s|m/s"),
    ("effort_nm", "joints.effort", "N·m|N"),
)


@dataclass
class JointStat:
    """One joint and quantity: RMS and worst error, when the worst was, when it first exceeded the
    tolerance (None: never), all at the sparser log's sample times (s from A's first sample)."""

    joint: str
    quantity: str  # a tolerance name: joints.position, joints.velocity, joints.effort
    unit: str
    tolerance: float
    rms: float
    worst: float
    worst_t_s: float
    parts_t_s: float | None

    @property
    def passed(self) -> bool:
        return self.parts_t_s is None


@dataclass
class LogComparison:
    """The verdict of two joint logs compared at the sparser one's sample times."""

    a: str
    b: str
    lag_s: float
    lag_from: str  # "first motion, best fit" or "--time-offset"
    samples: int  # sample times compared
    at: str  # which log's sample times: "A" or "B"
    rate_a_hz: float
    rate_b_hz: float
    stats: list[JointStat] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(s.passed for s in self.stats)

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1


def _first_motion_s(log: JointLog, columns: list[int]) -> float:
    q = log.position_rad[:, columns]
    moved = np.nonzero(np.any(np.abs(q - q[0]) > MOTION_RAD, axis=1))[0]
    if not len(moved):
        raise NotComparable(
            f"{log.path or 'a log'} never moves (no joint leaves its first value by "
            f"{MOTION_RAD} rad); expected a run to align on, or give --time-offset S"
        )
    return float(log.t_ns[moved[0]] - log.t_ns[0]) * 1e-9


def _relative_s(log: JointLog) -> np.ndarray:
    return (log.t_ns - log.t_ns[0]).astype(np.float64) * 1e-9


def _interp(t_s: np.ndarray, at_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(at_s, t_s, values[:, k]) for k in range(values.shape[1])], axis=1)


class _Pair:
    """The dense log (interpolated) and the sparse one (sampled), their common joints' columns."""

    def __init__(self, a: JointLog, b: JointLog, revolute: dict[str, bool]) -> None:
        common = [name for name in a.names if name in b.names]
        if not common:
            raise NotComparable(
                f"no joint in common: {a.path or 'A'} has {', '.join(a.names)}, "
                f"{b.path or 'B'} has {', '.join(b.names)}; expected the same names "
                "(or --joint-map ROBOT=TWIN)"
            )
        self.common = common
        self.revolute = np.array([revolute.get(name, False) for name in common])
        self.b_is_sparse = b.rate_hz <= a.rate_hz
        self.sparse, self.dense = (b, a) if self.b_is_sparse else (a, b)
        self.cols_s = [self.sparse.names.index(n) for n in common]
        self.cols_d = [self.dense.names.index(n) for n in common]
        self.ts, self.td = _relative_s(self.sparse), _relative_s(self.dense)

    def dense_times(self, lag_s: float) -> np.ndarray:
        """The sparse log's sample times on the dense log's clock."""
        return self.ts - lag_s if self.b_is_sparse else self.ts + lag_s

    def inside(self, lag_s: float) -> np.ndarray:
        at = self.dense_times(lag_s)
        return (at >= self.td[0]) & (at <= self.td[-1])

    def difference(self, attr: str, lag_s: float, keep: np.ndarray) -> np.ndarray:
        """The sparse log's values less the dense log's interpolated at its times (signed)."""
        at = self.dense_times(lag_s)[keep]
        dense = _interp(self.td, at, getattr(self.dense, attr)[:, self.cols_d])
        return getattr(self.sparse, attr)[keep][:, self.cols_s] - dense

    def error(self, attr: str, lag_s: float, keep: np.ndarray) -> np.ndarray:
        d = self.difference(attr, lag_s, keep)
        if attr != "position_rad":
            return np.abs(d)
        wrapped = np.abs((d + np.pi) % (2 * np.pi) - np.pi)
        return np.where(self.revolute & (np.abs(d) > np.pi), wrapped, np.abs(d))

    def cost(self, lag_s: float) -> float:
        """How badly the positions fit at this lag: the mean square of each joint's difference
        less its own mean, so that a joint off by a constant (a calibration offset) does not pull
        the lag away from where the motions line up."""
        keep = self.inside(lag_s)
        if keep.sum() < 2:
            return np.inf
        d = self.difference("position_rad", lag_s, keep)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a joint all NaN: no fit from it
            cost = np.nanmean((d - np.nanmean(d, axis=0)) ** 2)
        return float(cost) if np.isfinite(cost) else np.inf


def best_lag_s(pair: _Pair, a: JointLog, b: JointLog) -> float:
    """The lag from the first motions, then refined to the best fit within two sample intervals."""
    first = _first_motion_s(b, [b.names.index(n) for n in pair.common]) - _first_motion_s(
        a, [a.names.index(n) for n in pair.common]
    )
    step_s = 2.0 * max(np.median(np.diff(pair.ts)), np.median(np.diff(pair.td)))
    best, width = first, step_s
    for _ in range(4):  # each pass: 81 lags over the window, then a window four steps wide
        lags = best + np.linspace(-width, width, 81)
        costs = [pair.cost(lag) for lag in lags]
        best = float(lags[int(np.argmin(costs))])
        width = 4 * (2 * width / 80)
    return best


def _stat(label: str, name: str, unit: str, limit: float, e: np.ndarray, t_a: np.ndarray):
    """One row of the verdict from errors `e` at times `t_a` (s of A); a NaN (a value one log
    lacks at that sample) is beyond any tolerance."""
    e = np.where(np.isnan(e), np.inf, e)
    worst = int(np.argmax(e))
    over = np.nonzero(e > limit)[0]
    return JointStat(
        joint=label,
        quantity=name,
        unit=unit,
        tolerance=limit,
        rms=float(np.sqrt(np.mean(e**2))),
        worst=float(e[worst]),
        worst_t_s=float(t_a[worst]),
        parts_t_s=float(t_a[over[0]]) if len(over) else None,
    )


def _joint_stats(pair: _Pair, a, b, tol, lag_s: float, keep, notes: list[str]) -> list[JointStat]:
    """Each common joint's position, and velocity and effort where both logs carry them."""
    t_a = pair.dense_times(lag_s)[keep] if pair.b_is_sparse else pair.ts[keep]
    stats = []
    for attr, name, unit in QUANTITIES:
        missing = [
            log.path or "a log"
            for log in (a, b)
            if getattr(log, attr) is None or np.isnan(getattr(log, attr)).all()
        ]
        if missing:  # a driver without effort sensing sends NaN, or nothing
            notes.append(f"{name} not compared: {missing[0]} has none")
            continue
        if tol[name] == np.inf:
            continue
        err = pair.error(attr, lag_s, keep)
        stats += [
            _stat(label=joint, name=name, unit=unit, limit=tol[name], e=err[:, k], t_a=t_a)
            for k, joint in enumerate(pair.common)
        ]
    return stats


def _frame_stats(a: JointLog, b: JointLog, tol: Tolerances, lag_s: float) -> list[JointStat]:
    """Each /tf frame both logs have (the pad tip, the objects by name): the distance between its
    positions at the sparser series' times, the denser interpolated linearly there."""
    stats = []
    for frame in sorted(set(a.tf) & set(b.tf)):
        name = "pad.position" if frame == PAD_FRAME else "objects.position"
        (ta, pa), (tb, pb) = a.tf[frame], b.tf[frame]
        if len(ta) < 2 or len(tb) < 2 or tol[name] == np.inf:
            continue
        ua = (ta - a.t_ns[0]).astype(np.float64) * 1e-9
        ub = (tb - b.t_ns[0]).astype(np.float64) * 1e-9 - lag_s  # on A's clock
        if len(tb) <= len(ta):
            keep = (ub >= ua[0]) & (ub <= ua[-1])
            at, sparse = ub[keep], pb[keep, :3]
            dense = _interp(ua, at, pa[:, :3])
        else:
            keep = (ua >= ub[0]) & (ua <= ub[-1])
            at, sparse = ua[keep], pa[keep, :3]
            dense = _interp(ub, at, pb[:, :3])
        if len(at):
            e = np.linalg.norm(sparse - dense, axis=1)
            stats.append(_stat(label=frame, name=name, unit="m", limit=tol[name], e=e, t_a=at))
    return stats


def compare_logs(
    a: JointLog,
    b: JointLog,
    tol: Tolerances,
    *,
    revolute: dict[str, bool],
    lag_s: float | None = None,
) -> LogComparison:
    """A and B's common joints compared at the sparser log's samples (the denser interpolated
    linearly there), after aligning B on A (lag_s given, or best_lag_s)."""
    pair = _Pair(a, b, revolute)
    lag_from = "--time-offset" if lag_s is not None else "first motion, then best fit"
    if lag_s is None:
        lag_s = best_lag_s(pair, a, b)
    keep = pair.inside(lag_s)
    if keep.sum() < 2:
        raise NotComparable(
            f"with a lag of {lag_s:.6f} s the logs do not overlap; expected a lag within "
            f"their lengths ({pair.td[-1]:.3f} s and {pair.ts[-1]:.3f} s)"
        )
    result = LogComparison(
        a=a.path,
        b=b.path,
        lag_s=lag_s,
        lag_from=lag_from,
        samples=int(keep.sum()),
        at="B" if pair.b_is_sparse else "A",
        rate_a_hz=a.rate_hz,
        rate_b_hz=b.rate_hz,
    )
    result.stats += _joint_stats(
        pair=pair,
        a=a,
        b=b,
        tol=tol,
        lag_s=lag_s,
        keep=keep,
        notes=result.notes,
    )
    result.stats += _frame_stats(a, b, tol, lag_s)
    result.notes += [*a.notes, *b.notes]
    extra = [n for n in (*a.names, *b.names) if n not in pair.common]
    if extra:
        result.notes.append(f"not compared (in one log only): {', '.join(dict.fromkeys(extra))}")
    return result


def render_log_comparison(result: LogComparison) -> str:
    """The verdict, the alignment, then one line per joint and quantity."""
    verdict = "MATCH" if result.passed else "MISMATCH"
    lines = [
        f"{verdict}: {result.a} vs {result.b} (joint logs)",
        f"lag: B runs {result.lag_s:+.6f} s after A, from their first samples ({result.lag_from})",
        (
            f"compared at {result.samples} samples of {result.at} ({result.rate_a_hz:.1f} Hz A, "
            f"{result.rate_b_hz:.1f} Hz B), the other interpolated linearly there"
        ),
    ]
    failing = [s for s in result.stats if not s.passed]
    if failing:
        first = min(failing, key=lambda s: s.parts_t_s)
        lines.append(
            f"first divergence: {first.joint} {first.quantity} at t={first.parts_t_s:.3f} s "
            f"(of A): beyond {first.tolerance:g} {first.unit}"
        )
    lines.append(
        f"{'joint|frame':<16} {'field':<16} {'rms':>11} {'worst':>11} {'at t (s)':>9} "
        f"{'tol':>9}  ok"
    )
    for s in result.stats:
        ok = "yes" if s.passed else f"NO, from {s.parts_t_s:.3f} s"
        lines.append(
            f"{s.joint:<16} {s.quantity:<16} {s.rms:>11.3e} {s.worst:>11.3e} {s.worst_t_s:>9.3f} "
            f"{s.tolerance:>9.2e}  {ok}"
        )
    lines += [f"note: {note}" for note in result.notes]
    return "\n".join(lines)
