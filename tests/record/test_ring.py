"""The ring of rows the twin shares with its recorder processes: rows come back as they went in,
across the ring's end, and a recorder that falls behind makes the twin wait rather than lose or
overwrite rows."""

from __future__ import annotations

import time

import numpy as np
from support.runs import record_pick_place

from twin.record import process
from twin.record.mcap.reader import load
from twin.record.ring import FrameRing
from twin.record.rows import FrameRows
from twin.sim.twin import Twin

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


def test_the_twin_wakes_a_recorder_once_a_take_is_published(tmp_path, monkeypatch):
    """No timer: a recorder sleeps until the twin has published a take's worth of rows (TAKE_S,
    48 frames for the MCAP writer), so a run of N frames wakes it about N / 48 times."""
    made = _keep_made(monkeypatch)
    run = record_pick_place(tmp_path / "woken.mcap", background=True)
    (child,) = made[0]._children
    frames = len(run.frames)
    assert child.take == 48 and frames // 48 - 2 <= child.wakes <= frames // 48 + 2


def test_a_recorder_behind_the_twin_is_waited_for(tmp_path, monkeypatch):
    """A writer slower than the twin (2 ms a take, forked into the recorder) would let the twin run
    ahead: it waits once the MCAP writer lags MAX_AHEAD_S, and nothing is lost."""
    from twin.record.mcap.writer import McapRecorder

    made = _keep_made(monkeypatch)
    on_frames = McapRecorder.on_frames

    def slow(self, frames):
        time.sleep(0.002)
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
