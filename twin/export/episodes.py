"""Episodes cut from recordings and resampled to a whole number of frames per second.

An episode is a span of one recording's steps: the whole recording, or one pick-place cycle (from
the task's `cycle N: ...` phase event to the next cycle's, the last to the end of the recording).
Resampling takes the nearest recorded frame: dataset frame k of an episode starting at time t0 is the
recorded frame whose t_ns is nearest t0 + k / fps (the earlier of two as near; exact integer
arithmetic), so every value in a dataset is one the twin recorded, never an interpolation. Nearest,
not the last before: a step's t_ns is rounded to whole nanoseconds (240 Hz: 4166667 ns), so step 8k
lies 2.7k ns after k / 30 s, and "the last before" would take step 8k - 1.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError
from twin.model.recording import Recording

_CYCLE_PHASE = re.compile(r"cycle (\d+):")
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Episode:
    """One episode: its recording, the recording's frame rows it samples (one per dataset frame),
    and which span it is (`cycle` is 0 for a whole recording)."""

    rec: Recording
    rows: np.ndarray  # int64 indices into rec.frames, one per dataset frame
    t0_ns: int  # the simulated time of dataset frame 0
    cycle: int = 0

    def __len__(self) -> int:
        return int(self.rows.shape[0])


def spans(rec: Recording, mode: str) -> list[tuple[int, int, int]]:
    """(first step, end step exclusive, cycle) of each episode in rec: one for mode "recording",
    one per pick-place cycle for mode "cycles" (ConfigError if the recording has no cycle phases)."""
    if len(rec.frames) == 0:
        raise ConfigError(f"recording {rec.path!r} has no frames; expected at least one to export")
    last = int(rec.frames.step[-1]) + 1
    if mode == "recording":
        return [(int(rec.frames.step[0]), last, 0)]
    starts: dict[int, int] = {}
    for ev in rec.events:
        match = _CYCLE_PHASE.match(ev.message) if ev.kind == "phase" else None
        if match:
            starts.setdefault(int(match.group(1)), ev.step)
    if not starts:
        raise ConfigError(f"recording {rec.path!r} has no pick-place cycles (phase events 'cycle N: ...'); "
                          "expected a pick_place run, or --episodes recording")
    cycles = sorted(starts.items(), key=lambda item: item[1])
    ends = [step for _, step in cycles[1:]] + [last]
    return [(step, end, number) for (number, step), end in zip(cycles, ends, strict=True)]


def resample(rec: Recording, first_step: int, end_step: int, fps: int, cycle: int = 0) -> Episode:
    """The episode of rec's frames with first_step <= step < end_step, at fps frames per second."""
    steps, t_ns = rec.frames.step, rec.frames.t_ns
    inside = np.nonzero((steps >= first_step) & (steps < end_step))[0]
    if inside.size == 0:
        raise ConfigError(f"recording {rec.path!r} has no frame between steps {first_step} and {end_step}")
    lo, hi = int(inside[0]), int(inside[-1])
    t0 = int(t_ns[lo])
    span_ns = int(t_ns[hi]) - t0
    count = span_ns * fps // NS_PER_S + 1  # frames k with k / fps <= span
    rows = lo + nearest((t_ns[lo:hi + 1] - t0) * fps, np.arange(count, dtype=np.int64) * NS_PER_S)
    return Episode(rec, rows, t0, cycle)


def nearest(times: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """For each wanted time, the index of the nearest of the sorted times (the earlier of two as near).
    Both in the same integer unit (here ns × fps), so the choice is exact."""
    after = np.clip(np.searchsorted(times, wanted, side="left"), 0, len(times) - 1)
    before = np.maximum(after - 1, 0)
    take_before = np.abs(wanted - times[before]) <= np.abs(times[after] - wanted)
    return np.where(take_before, before, after).astype(np.int64)


def episodes(recordings: list[Recording], fps: int, mode: str) -> list[Episode]:
    """Every episode of the recordings, in order (mode "recording" or "cycles")."""
    return [resample(rec, first, end, fps, cycle) for rec in recordings for first, end, cycle in spans(rec, mode)]
