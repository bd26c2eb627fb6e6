"""Episodes cut from recordings and resampled to a whole number of frames per second.

An episode is a span of one recording's steps: the whole recording, or one pick-place cycle (from
the task's `cycle N: ...` phase event to the next cycle's, the last to the end of the recording).
Resampling takes the nearest recorded frame: dataset frame k of an episode starting at time t0 is
the recorded frame whose t_ns is nearest t0 + k / fps (the earlier of two as near; exact integer
arithmetic), so every value in a dataset is one the twin recorded, never an interpolation. Nearest,
not the last before: a step's t_ns is rounded to whole nanoseconds (240 Hz: 4166667 ns), so step 8k
lies 2.7k ns after k / 30 s, and "the last before" would take step 8k - 1.

Bounds, checked before anything is allocated: --fps at most the recording's physics rate (a faster
dataset only repeats steps: max_fps), every frame's time its step times the time step (a file whose
times disagree is damaged: check_times), and at most MAX_DATASET_FRAMES frames in all (memory grows
with them: about 200 bytes each).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from twin.model.errors import ConfigError, RecordingError
from twin.model.recording import Recording

_CYCLE_PHASE = re.compile(r"cycle (\d+):")
NS_PER_S = 1_000_000_000
# the fastest physics rate a twin runs at (model.config: time steps of 1e5..1e8 ns)
MAX_FPS = 10_000
# one export: 2.3 h at 240 fps, 18.5 h at 30 fps (about 400 MB while written)
MAX_DATASET_FRAMES = 2_000_000


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
    """(first step, end step exclusive, cycle) of each episode in rec: one for mode "recording", one
    per pick-place cycle for mode "cycles" (ConfigError if the recording has no cycle phases)."""
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
        raise ConfigError(
            f"recording {rec.path!r} has no pick-place cycles (phase events 'cycle N: ...'); "
            "expected a pick_place run, or --episodes recording"
        )
    cycles = sorted(starts.items(), key=lambda item: item[1])
    ends = [step for _, step in cycles[1:]] + [last]
    return [(step, end, number) for (number, step), end in zip(cycles, ends, strict=True)]


def max_fps(rec: Recording) -> int:
    """The highest --fps for rec: its physics rate (steps per second, rounded: 240 for 4166667
    ns)."""
    return max(1, round(NS_PER_S / rec.config.dt_ns))


def check_fps(rec: Recording, fps: int) -> None:
    """ConfigError unless 1 <= fps <= rec's physics rate: faster, dataset frames would only repeat
    steps (and their number, memory and time grow with fps, not with the recording)."""
    top = max_fps(rec)
    if isinstance(fps, bool) or not isinstance(fps, int) or fps < 1:
        raise ConfigError(f"--fps {fps!r:.30} is invalid; expected a whole number 1..{top}")
    if fps > top:
        raise ConfigError(
            f"--fps {fps} is above the physics rate of recording {rec.path!r} ({top} steps per "
            f"second): its dataset frames would only repeat steps; expected --fps 1..{top}"
        )


def check_times(rec: Recording) -> None:
    """RecordingError unless every frame's time is its step times the time step (as the twin records
    them): resampling goes by time, so a damaged time could ask for any number of dataset frames."""
    f, dt_ns = rec.frames, rec.config.dt_ns
    wrong = np.nonzero(f.t_ns != f.step * dt_ns)[0]
    if wrong.size:
        i = int(wrong[0])
        raise RecordingError(
            f"recording {rec.path!r}: the frame at step {int(f.step[i])} has time "
            f"{int(f.t_ns[i])} ns; "
            f"expected step x {dt_ns} ns = {int(f.step[i]) * dt_ns} ns"
        )


def frame_count(rec: Recording, first_step: int, end_step: int, fps: int) -> tuple[int, int, int]:
    """(first row, last row, dataset frames) of the episode of rec's frames with first_step <= step
    < end_step at fps: frames k with k / fps <= its span. Nothing allocated."""
    steps = rec.frames.step
    lo = int(np.searchsorted(steps, first_step, side="left"))
    hi = int(np.searchsorted(steps, end_step, side="left")) - 1
    if hi < lo:
        raise ConfigError(
            f"recording {rec.path!r} has no frame between steps {first_step} and {end_step}"
        )
    span_ns = int(rec.frames.t_ns[hi]) - int(rec.frames.t_ns[lo])
    return lo, hi, span_ns * fps // NS_PER_S + 1


def resample(rec: Recording, first_step: int, end_step: int, fps: int, cycle: int = 0) -> Episode:
    """The episode of rec's frames with first_step <= step < end_step, at fps frames per second."""
    lo, hi, count = frame_count(rec, first_step, end_step, fps)
    t_ns = rec.frames.t_ns
    t0 = int(t_ns[lo])
    rows = lo + nearest((t_ns[lo : hi + 1] - t0) * fps, np.arange(count, dtype=np.int64) * NS_PER_S)
    return Episode(rec, rows, t0, cycle)


def nearest(times: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """For each wanted time, the index of the nearest of the sorted times (the earlier of two as
    near). Both in the same integer unit (here ns × fps), so the choice is exact."""
    after = np.clip(np.searchsorted(times, wanted, side="left"), 0, len(times) - 1)
    before = np.maximum(after - 1, 0)
    take_before = np.abs(wanted - times[before]) <= np.abs(times[after] - wanted)
    return np.where(take_before, before, after).astype(np.int64)


def episodes(recordings: list[Recording], fps: int, mode: str) -> list[Episode]:
    """Every episode of the recordings, in order (mode "recording" or "cycles"). Checks the bounds
    first (fps, frame times, MAX_DATASET_FRAMES in all): ConfigError or RecordingError, nothing
    allocated."""
    for rec in recordings:
        check_fps(rec, fps)
        check_times(rec)
    cut = [(rec, first, end, cycle) for rec in recordings for first, end, cycle in spans(rec, mode)]
    total = 0
    for rec, first, end, _ in cut:
        total += frame_count(rec, first, end, fps)[2]
        if total > MAX_DATASET_FRAMES:
            seconds = sum(int(r.frames.t_ns[-1] - r.frames.t_ns[0]) for r in recordings) / NS_PER_S
            raise ConfigError(
                f"the dataset would hold more than {MAX_DATASET_FRAMES:,} frames "
                f"({seconds:.1f} s of "
                f"recordings at --fps {fps}); expected at most {MAX_DATASET_FRAMES:,}: "
                f"lower --fps, "
                "or export the recordings in parts"
            )
    return [resample(rec, first, end, fps, cycle) for rec, first, end, cycle in cut]
