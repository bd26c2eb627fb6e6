"""Crash safety: a run killed with SIGKILL, or a file cut anywhere, is restored by `twin
recover`."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import twin
from twin.cli import main
from twin.model.config import TwinConfig
from twin.record.mcap import schemas as S
from twin.record.mcap.recover import recover
from twin.sim.twin import Twin
from twin.tasks import run_task
from twin.verify.collectors import FrameCollector

LOOP_TASK = '''"""Moves between three points forever, reporting simulated time \
(a crash-test task)."""
import time


def run(twin, seconds=1e9, pace_s=0.02):
    points = [(0.5, 0.2), (0.3, 0.6), (-0.2, 0.5)]
    i = 0
    twin.suction(True)
    while twin.t_s < seconds:
        twin.move_to(*points[i % 3], settle=False)
        twin.wait(0.25)
        print(f"t_s={twin.t_s!r}", flush=True)
        time.sleep(pace_s)  # keep the run slow enough to be killed mid-way
        i += 1
'''


def _rerun(task_path: Path, seconds: float) -> FrameCollector:
    spec = importlib.util.spec_from_file_location("loop_task", task_path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    collector = FrameCollector()
    t = Twin(TwinConfig(), sinks=[collector])
    run_task(t, module.run, {"seconds": seconds, "pace_s": 0.0})
    t.close()
    return collector


def test_a_killed_run_is_recovered_but_for_at_most_the_last_second(tmp_path, capsys):
    task = tmp_path / "loop.py"
    task.write_text(LOOP_TASK)
    broken = tmp_path / "killed.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "run", str(task), "--record", str(broken)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    reported_s = 0.0
    try:
        for line in proc.stdout:
            if line.startswith("t_s="):
                reported_s = float(line[4:])
                if reported_s >= 4.0:
                    break
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert reported_s >= 4.0, proc.stderr.read()

    assert not broken.exists()  # a recording is renamed into place only when finalized
    assert main(["info", str(broken) + ".partial"]) == 2
    out, err = capsys.readouterr()
    assert "finalized: no" in out and "not finalized" in err
    fixed = tmp_path / "fixed.mcap"
    assert main(["recover", str(broken), "-o", str(fixed)]) == 0  # finds killed.mcap.partial
    rec = twin.load(fixed)
    kept_s = rec.frames.t_ns[-1] * 1e-9
    assert kept_s >= reported_s - 1.0, f"lost {reported_s - kept_s:.3f} s of simulated time"
    assert not rec.finalized and rec.meta[S.META_RECOVERED]["source"] == "killed.mcap.partial"
    capsys.readouterr()
    assert main(["info", str(fixed)]) == 0
    assert "finalized: no - recovered from killed.mcap.partial" in capsys.readouterr().out

    # runs are deterministic: the recovered part equals the same run made again in memory
    again = _rerun(task, kept_s + 0.5)
    assert rec.frames.equals(again.columns().slice(0, len(rec.frames)))
    last = int(rec.frames.step[-1])
    # (the task_start event, a Command too, names how the task was loaded and its parameters, which
    # differ here)
    assert rec.commands[1:] == [c for c in again.commands if c.step <= last][1:]
    assert rec.events[1:] == [e for e in again.events if e.step <= last][1:]


@pytest.fixture(scope="module")
def complete(pick_place_mcap) -> tuple[Path, FrameCollector]:
    """(path, collector) of one finalized pick_place cycle: the session's shared recording."""
    return pick_place_mcap


@pytest.mark.parametrize("fraction", [0.05, 0.3, 0.61, 0.9, 0.999])
def test_a_file_cut_anywhere_recovers_to_a_prefix_of_the_run(complete, tmp_path, fraction):
    path, collector = complete
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(twin.model.errors.RecordingError, match="twin recover"):
        twin.load(cut)
    report = recover(cut, tmp_path / "fixed.mcap")
    rec = twin.load(tmp_path / "fixed.mcap")
    n = len(rec.frames)
    assert n == report.frames
    assert rec.frames.equals(collector.columns().slice(0, n))
    last = int(rec.frames.step[-1]) if n else -1
    assert rec.commands == [c for c in collector.commands if c.step <= last]
    assert rec.events == [e for e in collector.events if e.step <= last]
    lost_s = (collector.frames[-1].t_ns - (rec.frames.t_ns[-1] if n else 0)) * 1e-9
    total_s = collector.frames[-1].t_ns * 1e-9
    assert lost_s <= (1.0 - fraction) * total_s + 1.0  # what was cut, plus at most a second


def test_recovering_a_complete_file_keeps_everything(complete, tmp_path):
    path, collector = complete
    report = recover(path, tmp_path / "copy.mcap")
    assert report.was_complete and report.messages_dropped == 0
    rec = twin.load(tmp_path / "copy.mcap")
    assert rec.frames.equals(collector.columns()) and rec.finalized


def test_recover_refuses_to_overwrite_its_input(complete, capsys):
    path, _ = complete
    before = path.read_bytes()
    assert main(["recover", str(path), "-o", str(path)]) == 2
    assert "overwrite its input" in capsys.readouterr().err
    assert path.read_bytes() == before


def test_a_damaged_chunk_is_reported_and_recovery_stops_before_it(complete, tmp_path):
    path, collector = complete
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    # zero 64 bytes inside a chunk: its CRC or its compression fails
    data[middle : middle + 64] = bytes(64)
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    with pytest.raises(twin.model.errors.RecordingError, match="damaged"):
        twin.load(damaged)
    recover(damaged, tmp_path / "fixed.mcap")
    rec = twin.load(tmp_path / "fixed.mcap")
    assert 0 < len(rec.frames) < len(collector.frames)
    assert rec.frames.equals(collector.columns().slice(0, len(rec.frames)))


@pytest.mark.parametrize("rate", [1, 1000])
def test_a_file_still_being_written_holds_all_but_the_last_second(complete, tmp_path, rate):
    from twin.record.mcap.reader import recording_from_scan, scan
    from twin.record.mcap.writer import McapRecorder
    from twin.robot.urdf import urdf_text

    _, collector = complete
    config = TwinConfig()
    live = tmp_path / "live.mcap"
    recorder = McapRecorder(
        live,
        config,
        {"source": "task", "task": "x", "params": {}},
        urdf=urdf_text(config.profile),
        rate=rate,
    )
    for frame in collector.frames:
        recorder.on_frame(frame)
        for event in [e for e in collector.events if e.step == frame.step]:
            recorder.on_event(event)
        if frame.step % 97 == 0:  # look at the file as a crash would leave it, now and then
            s = scan(str(live) + ".partial", strict=False)
            assert not s.complete
            by_topic = s.by_topic()
            newest_ns = max([m.log_time for m in by_topic[S.TF.topic]], default=0)
            assert frame.t_ns - newest_ns <= 1_000_000_000
            rec = recording_from_scan(s)
            if rate == 1:
                assert frame.t_ns - (rec.frames.t_ns[-1] if len(rec.frames) else 0) <= 1_000_000_000
    recorder.close()
    assert twin.load(live).finalized


def test_recovering_a_run_that_left_no_file_says_so(tmp_path, capsys, monkeypatch):
    """Neither the recording nor its .partial file: one line naming both, exit 2 (not a hint about
    -o)."""
    monkeypatch.chdir(tmp_path)
    assert main(["recover", "runs/killed.mcap"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "twin: error: recording 'runs/killed.mcap' does not exist, nor does "
        "'runs/killed.mcap.partial'; "
        "expected a recording or the .partial file a killed run left\n"
    )
