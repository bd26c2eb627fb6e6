"""The ring of rows the twin shares with its recorder processes: rows come back as they went in,
across the ring's end, and a recorder that falls behind makes the twin wait rather than lose or
overwrite rows."""

from __future__ import annotations

import itertools
import time

import numpy as np
from support.runs import record_pick_place

from twin.model.config import TwinConfig
from twin.record import open_recorders, process
from twin.record.mcap.reader import load
from twin.record.mcap.writer import McapRecorder, flush_steps
from twin.record.ring import FrameRing
from twin.record.rows import FrameRows
from twin.sim.twin import Twin

RUN = {"source": "task", "task": "steps", "params": {}}
FOUR_CYCLES = {"cycles": 4}  # about 4,480 frames: more than the ring's 4,096 rows at 240 Hz


def test_rows_come_back_in_order_across_the_rings_end():
    twin = Twin()
    rows = FrameRows(4, 1)
    ring = FrameRing(rows, capacity=5, readers=1)
    frames = []
    for written in range(8):
        frames.append(twin.step())
        rows.pack_into(ring.memory, ring.offset(written), frames[-1])
    twin.close()
    assert ring.publish(8) == [0]
    runs = ring.runs(3, 8)
    # rows 3-4 at the ring's end, 5-7 from its start
    assert [len(run) for run in runs] == [2, 3]
    steps = np.concatenate([run.step for run in runs])
    assert steps.tolist() == [f.step for f in frames[3:8]]
    assert runs[1].frame(2) == frames[7]
    ring.release(0, 8)
    assert ring.read(0) == 8 and ring.written() == 8


def test_a_run_longer_than_the_ring_makes_the_same_bytes_as_the_in_process_writer(tmp_path):
    record_pick_place(tmp_path / "bg.mcap", params=FOUR_CYCLES, background=True)
    record_pick_place(tmp_path / "fg.mcap", params=FOUR_CYCLES, background=False)
    assert len(load(tmp_path / "bg.mcap").frames) > 4096
    assert (tmp_path / "bg.mcap").read_bytes() == (tmp_path / "fg.mcap").read_bytes()


def test_the_twin_wakes_a_recorder_just_after_each_flush_frame(tmp_path, monkeypatch):
    """No timer: a recorder sleeps until the twin has published a frame at which the MCAP writer
    flushes its file (every 0.5 s of simulated time, 120 frames at 240 Hz), so a run wakes it once a
    flush, once to close, and when the twin has to wait for it."""
    made = _keep_made(monkeypatch)
    woken: list[int] = []
    wake = process._Child.wake
    monkeypatch.setattr(
        process._Child,
        "wake",
        lambda self, written, others: (woken.append(written), wake(self, written, others)),
    )
    run = record_pick_place(tmp_path / "woken.mcap", background=True)
    frames = len(run.frames)
    flushes = list(itertools.takewhile(lambda s: s < frames, flush_steps(run.config.dt_ns, 1)))
    assert flushes[:3] == [179, 299, 419]
    # each flush frame's row is published at the next publish (every 16 frames) and woken for then
    for step in flushes:
        assert any(step < written <= step + 16 for written in woken), (step, woken)
    assert len(flushes) + 1 <= len(woken) <= len(flushes) + 1 + made[0].waits


def test_without_an_mcap_file_the_twin_wakes_a_recorder_once_a_take_has_gathered(tmp_path):
    """The Rerun writer alone takes rows in RRD_TAKE_S at a time (1,024 frames): it is woken for
    no fewer."""
    config = TwinConfig()
    with open_recorders(config, RUN, mcap_path=None, rrd_path=tmp_path / "v.rrd") as sinks:
        twin = Twin(config, sinks=sinks)
        twin.step(3000)
        twin.close()
    (child,) = sinks[0]._children
    assert child.wakes == 3000 // 1024 + 1  # and the close's


def test_a_recorder_behind_the_twin_is_waited_for(tmp_path, monkeypatch):
    """A writer slower than the twin (20 ms a take, forked into the recorder) would let the twin
    run ahead: it waits once it is MAX_AHEAD_S past a flush frame the MCAP writer has not taken in,
    and nothing is lost."""
    made = _keep_made(monkeypatch)
    on_frames = McapRecorder.on_frames

    def slow(self, frames):
        time.sleep(0.02)
        on_frames(self, frames)

    monkeypatch.setattr(McapRecorder, "on_frames", slow)
    record_pick_place(tmp_path / "slow.mcap", background=True)
    monkeypatch.undo()
    record_pick_place(tmp_path / "fg.mcap", background=False)
    assert made[0].waits > 3
    assert (tmp_path / "slow.mcap").read_bytes() == (tmp_path / "fg.mcap").read_bytes()


def _keep_made(monkeypatch) -> list:
    """The RecorderProcess objects made while the patch lasts."""
    made = []
    original = process.RecorderProcess.__init__

    def keep(self, *args, **kwargs):
        original(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(process.RecorderProcess, "__init__", keep)
    return made
