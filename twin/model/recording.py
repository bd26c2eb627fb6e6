"""A recording in memory: what `twin.load(path)` returns and what replay and compare consume."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.images import CameraTrack
from twin.model.types import Command, Event

# the metadata record a cleanly closed file ends with (outcome, error)
META_FINALIZED = "twin.finalized"
META_RECORDING = "twin.recording"  # the recording's layout: rate_steps, block_frames, ...
META_MACHINE = "twin.machine"  # where it was made: cpu, blas_core, ...; older files have none


@dataclass
class Recording:
    """Everything one run produced, plus how to rebuild it (twin.load and a replay give it with its
    tables: record.tables.RecordingWithTables).

    Attributes:
        config: the configuration that rebuilds the run (robot profile, scene, time step, engine).
        frames: one row a kept physics step, as numpy columns (`step`, `t_ns`, `joint_q`, ...).
        commands: every input, at every step whatever the frame rate.
        events: what the twin and the task said (attach, release, placed, phases, ...).
        run: `{"source": "task"|"teleop"|"remote", "task": name or path or "", "params": {...}}`.
        meta: the rest of the file's metadata (versions, platform, engine, ...).
        finalized: the file was closed cleanly.
        urdf: the robot's URDF text.
        path: the file it was loaded from ("" in memory).
        assets: attachments (robot.urdf and meshes) by name.
        cameras: each camera's pictures, by camera name.
    """

    config: TwinConfig
    frames: FrameColumns
    commands: list[Command]
    events: list[Event]
    run: dict
    meta: dict = field(default_factory=dict)
    finalized: bool = False
    urdf: str = ""
    path: str = ""
    # attachments: robot.urdf and meshes, by name
    assets: dict[str, bytes] = field(default_factory=dict)
    # each camera's pictures, by camera name
    cameras: dict[str, CameraTrack] = field(default_factory=dict)

    @property
    def outcome(self) -> str:
        """How the run's task ended: the finalized outcome in its file (ok, error, interrupted);
        unfinished for a file that was never finalized (cut short, also once recovered); and error
        whenever a task_error event says so (a run kept in memory has only its events)."""
        if self.path and not self.finalized:
            return "unfinished"
        outcome = str((self.meta.get(META_FINALIZED) or {}).get("outcome", "ok"))
        if outcome == "ok" and any(e.kind == "task_error" for e in self.events):
            outcome = "error"
        return outcome

    @property
    def machine(self) -> dict[str, str]:
        """Where the file was made (its twin.machine record: cpu, cpu_flags, blas_core, libc,
        libm_hwcaps, numpy_simd); empty in memory and in files written before the record."""
        return dict(self.meta.get(META_MACHINE) or {})

    @property
    def rate_steps(self) -> int:
        """Every how many physics steps the file keeps a frame (1: every step): its layout metadata,
        or, without it, the frames' own spacing."""
        try:
            rate = int((self.meta.get(META_RECORDING) or {}).get("rate_steps", 1))
        except (TypeError, ValueError):
            rate = 1
        steps = self.frames.step
        if rate <= 1 and len(steps) > 2:
            rate = int(np.min(np.diff(steps[:-1])))
        return max(1, rate)
