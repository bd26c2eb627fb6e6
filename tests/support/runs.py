"""One pick_place run, made one way for every test: in memory, or recorded to MCAP through the real
recorders (open_recorders), as `twin run pick_place` records it."""

from __future__ import annotations

import hashlib
from dataclasses import fields
from pathlib import Path

from twin.model.columns import FrameColumns
from twin.model.config import TwinConfig
from twin.model.recording import Recording
from twin.record import open_recorders
from twin.sim.world import engine_versions
from twin.verify.check import record_task
from twin.verify.collectors import FrameCollector

ONE_CYCLE = {"cycles": 1}


def pick_place_run(params: dict = ONE_CYCLE) -> dict:
    """The run description a recording of pick_place with params stores."""
    return {"source": "task", "task": "pick_place", "params": dict(params)}


def record_pick_place(
    path: Path | None = None,
    config: TwinConfig | None = None,
    params: dict = ONE_CYCLE,
    *,
    rate: int = 1,
    background: bool = True,
    sinks=(),
) -> Recording:
    """pick_place on a fresh twin in real PyBullet, recorded to `path` (every `rate`th step, by a
    recorder process unless background=False) when a path is given; returns the run in memory.
    `sinks` see it too."""
    config = config or TwinConfig()
    if path is None:
        return record_task(config, "pick_place", params, sinks=sinks)
    with open_recorders(
        config,
        pick_place_run(params),
        mcap_path=path,
        rate=rate,
        background=background,
        engine=engine_versions(),
    ) as files:
        return record_task(config, "pick_place", params, sinks=[*sinks, *files])


def collect_pick_place(
    path: Path | None = None, config: TwinConfig | None = None, params: dict = ONE_CYCLE, **options
) -> FrameCollector:
    """record_pick_place, returning a FrameCollector of the frames, commands and events the twin
    sent."""
    collector = FrameCollector()
    record_pick_place(path, config, params, sinks=[collector], **options)
    return collector


def columns_digest(cols: FrameColumns) -> str:
    """sha256 over every column's dtype, shape and bytes, in field order."""
    h = hashlib.sha256()
    for f in fields(cols):
        a = getattr(cols, f.name)
        h.update(f"{f.name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()
