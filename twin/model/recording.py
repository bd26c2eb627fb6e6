"""A recording in memory: what `twin.load(path)` returns and what replay and compare consume."""

from __future__ import annotations

from dataclasses import dataclass, field

from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.types import Command, Event

META_FINALIZED = "twin.finalized"  # the metadata record a cleanly closed file ends with (outcome, error)


@dataclass
class Recording:
    """Everything one run produced, plus how to rebuild it.

    run: {"source": "task"|"teleop"|"remote", "task": name or path or "", "params": {...}}
    meta: the rest of the file's metadata (versions, platform, engine, ...), as strings.
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
    assets: dict[str, bytes] = field(default_factory=dict)  # attachments: robot.urdf and meshes, by name
