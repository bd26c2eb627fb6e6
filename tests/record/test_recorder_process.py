"""Recording in a recorder process: the same files as in-process writers, errors at once, and a
run whose process dies leaves a recoverable, unfinalized file."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from support.runs import record_pick_place

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, RecordingError
from twin.record import open_recorders
from twin.record.mcap import schemas as S
from twin.record.mcap.reader import load, scan
from twin.record.mcap.recover import recover
from twin.record.outputs import partial_path
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task

RUN = {"source": "task", "task": "pick_place", "params": {"cycles": 1}}


def _record(path, *, background: bool, data=None) -> None:
    """One pick_place cycle recorded to path; with data, a note event carrying it comes first."""
    if data is None:
        record_pick_place(path, background=background)
        return
    config = TwinConfig()
    with open_recorders(config, RUN, mcap_path=path, background=background) as sinks:
        twin = Twin(config, sinks=sinks)
        twin.event("note", message="odd data", value=data)
        run_task(twin, TASKS["pick_place"], {"cycles": 1})
        twin.close()


def test_background_and_in_process_writers_make_the_same_bytes(tmp_path):
    _record(tmp_path / "bg.mcap", background=True)
    _record(tmp_path / "fg.mcap", background=False)
    assert (tmp_path / "bg.mcap").read_bytes() == (tmp_path / "fg.mcap").read_bytes()
    assert load(tmp_path / "bg.mcap").finalized


def test_event_data_marshal_cannot_carry_still_arrives(tmp_path):
    _record(tmp_path / "np.mcap", background=True, data=np.float64(0.25))
    notes = [e for e in load(tmp_path / "np.mcap").events if e.kind == "note"]
    assert len(notes) == 1 and notes[0].data["value"] == 0.25


def test_a_writer_that_cannot_start_fails_at_once_in_one_line(tmp_path):
    (tmp_path / "a_file").write_text("not a folder")
    impossible = tmp_path / "a_file" / "x.mcap"
    with (
        pytest.raises(RecordingError) as err,
        open_recorders(TwinConfig(), RUN, mcap_path=impossible),
    ):
        pytest.fail("the block must not run when the recorder cannot start")
    assert "a_file" in str(err.value) and "\n" not in str(err.value)


def _killed_run(path, late_event: bool) -> subprocess.CompletedProcess:
    """A run recorded to path whose process kills itself after a move and a 5 s wait (and 40 steps:
    past the wake-up for the flush at step 1379), 20 frames after an event the recorder was never
    sent (late_event) or with none since the twin last woke it."""
    script = textwrap.dedent(f"""
        import os, signal
        from twin.model.config import TwinConfig
        from twin.record import open_recorders
        from twin.sim.twin import Twin
        config = TwinConfig()
        with open_recorders(config, {RUN!r}, mcap_path={str(path)!r}) as sinks:
            twin = Twin(config, sinks=sinks)
            twin.move_to(0.3, 0.3)
            twin.wait(5.0)
            twin.step(40)
            if {late_event!r}:
                twin.event("late", message="never sent")
                twin.step(20)
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    return subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )


def _recovered(path, tmp_path):
    """The killed run's file, recovered: its Recording."""
    partial = partial_path(path)  # the file is renamed to path only when finalized
    # the orphaned recorder writes what it got once it sees the pipe close
    _wait_until_settled(partial)
    assert not path.exists()
    kept = scan(partial, strict=False)
    assert not kept.complete and S.META_FINALIZED not in kept.metadata
    fixed = tmp_path / "fixed.mcap"
    recover(path, fixed)
    return load(fixed)


def test_a_run_whose_process_dies_leaves_every_published_frame(tmp_path):
    """With nothing the recorder was not sent, it keeps every row the twin published (one every
    16 frames): at most the last 15 frames are lost."""
    path = tmp_path / "killed.mcap"
    done = _killed_run(path, late_event=False)
    assert done.returncode == -signal.SIGKILL, done.stderr
    last_step = int(_recovered(path, tmp_path).frames.step[-1])
    assert twin_steps() - 16 <= last_step < twin_steps()


def test_a_run_whose_process_dies_keeps_no_frame_after_an_event_it_lost(tmp_path):
    """An event kept for the next wake-up dies with the twin: the recorder keeps the rows before
    it, none after it, so the file never shows what came after an event it does not hold."""
    path = tmp_path / "killed.mcap"
    done = _killed_run(path, late_event=True)
    assert done.returncode == -signal.SIGKILL, done.stderr
    rec = _recovered(path, tmp_path)
    assert "late" not in [e.kind for e in rec.events]
    # the event came at step twin_steps(): its frame is the last that may be kept
    assert twin_steps() - 16 <= int(rec.frames.step[-1]) <= twin_steps()


def twin_steps() -> int:
    """Steps the killed run had made before the kill (or before the late event): the move, the 5 s
    wait and 40 steps, as a fresh run shows."""
    twin = Twin()
    twin.move_to(0.3, 0.3)
    twin.wait(5.0)
    twin.step(40)
    return twin.step_index


def _wait_until_settled(path, timeout_s: float = 10.0) -> None:
    deadline, last, stable = time.monotonic() + timeout_s, -1, 0
    while time.monotonic() < deadline and stable < 5:
        size = path.stat().st_size if path.exists() else -1
        stable = stable + 1 if size == last and size > 0 else 0
        last = size
        time.sleep(0.05)
    assert stable >= 5, f"{path} kept changing or never appeared"


def test_a_writer_error_mid_run_is_one_line_and_keeps_what_came_before(tmp_path):
    """A full disk, for real: the recorder may write only so many bytes (RLIMIT_FSIZE), then gets
    EFBIG."""
    path = tmp_path / "full.mcap"
    script = textwrap.dedent(f"""
        import resource, signal, sys
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit: EFBIG, no signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, resource.RLIM_INFINITY))
        from twin.cli import main
        sys.exit(main(["run", "pick_place", "--cycles", "4", "--record", {str(path)!r}]))
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert "recording stopped by a writer error" in done.stderr
    fixed = tmp_path / "fixed.mcap"
    recover(path, fixed)
    assert len(load(fixed).frames) > 100  # the part written before the disk filled up


def test_twin_events_carry_plain_json_data_and_refuse_the_rest():
    twin = Twin()
    event = twin.event("measure", value=np.float64(0.25), point=np.array([1.0, 2.0]), pair=(1, 2))
    assert event.data == {"pair": [1, 2], "point": [1.0, 2.0], "value": 0.25}
    assert type(event.data["value"]) is float
    with pytest.raises(ConfigError, match="'set'"):
        twin.event("measure", tags={"a", "b"})  # a set's order varies between runs


def test_an_unreadable_mesh_leaves_an_existing_recording_alone(tmp_path):
    from twin.record.mcap.writer import McapRecorder

    path = tmp_path / "keep.mcap"
    path.write_bytes(b"an earlier recording")
    with pytest.raises(RecordingError, match="no_such_mesh.stl"):
        McapRecorder(
            path, TwinConfig(), RUN, urdf="<robot/>", meshes=[tmp_path / "no_such_mesh.stl"]
        )
    assert path.read_bytes() == b"an earlier recording"


def _run_with_a_folder_in_the_way(tmp_path, name: str, *, steps: int):
    """A run recorded to x.mcap and x.rrd in tmp_path, a folder made at `name` first (a writer's
    NAME.partial: the path checks before the fork do not see it); the RecordingError it stops
    with."""
    (tmp_path / name).mkdir()
    config = TwinConfig()
    with (
        pytest.raises(RecordingError) as err,
        open_recorders(
            config, RUN, mcap_path=tmp_path / "x.mcap", rrd_path=tmp_path / "x.rrd"
        ) as sinks,
    ):
        Twin(config, sinks=sinks).step(steps)
    return err


def test_a_writer_that_fails_after_the_checks_stops_the_run_in_one_line(tmp_path):
    """The recorders start beside the twin's scene: a writer that fails in its process (here its
    NAME.partial is a folder, which the path checks before the fork do not see) stops the run at
    the twin's first publish, in one line, and the other writer ends as error."""
    err = _run_with_a_folder_in_the_way(tmp_path, "x.mcap.partial", steps=100)
    assert "x.mcap" in str(err.value) and "\n" not in str(err.value)
    assert "could not start" in str(err.value) or "cannot write" in str(err.value)
    assert not (tmp_path / "x.mcap").exists()
    assert (tmp_path / "x.rrd").exists()  # the view ended as error, finished


def test_a_view_that_fails_to_start_beside_the_run_stops_it_in_one_line(tmp_path):
    """The Rerun writer starts in a thread of the recorder while the MCAP one is fed: when it
    cannot (its NAME.partial is a folder), the run stops in one line and the MCAP file ends as
    error, finalized."""
    err = _run_with_a_folder_in_the_way(tmp_path, "x.rrd.partial", steps=2000)
    assert "x.rrd.partial" in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "x.rrd").exists()
    assert load(tmp_path / "x.mcap").meta[S.META_FINALIZED]["outcome"] == "error"


def test_a_run_that_fails_before_its_first_frame_still_says_how_it_ended(tmp_path):
    """The recorder is forked at the twin's first Frame: a run that never makes one (its scene
    fails to build) still gets both files, the MCAP one finalized as error."""
    with (
        pytest.raises(ValueError),
        open_recorders(
            TwinConfig(), RUN, mcap_path=tmp_path / "x.mcap", rrd_path=tmp_path / "x.rrd"
        ),
    ):
        raise ValueError("no scene")
    finalized = load(tmp_path / "x.mcap").meta[S.META_FINALIZED]
    assert finalized["outcome"] == "error" and "no scene" in finalized["error"]
    assert finalized["frames"] == "0" and (tmp_path / "x.rrd").exists()


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: the recorders share it")
def test_the_recorders_and_the_twin_keep_to_cores_of_their_own(tmp_path):
    """While it records (from the twin's first Frame, when the recorder is forked), the twin's
    thread keeps to the CPU it was on and the recorder (one process for both writers) to every
    other one; afterwards the thread may run where it could before."""
    config = TwinConfig()
    before = os.sched_getaffinity(0)
    with open_recorders(
        config, RUN, mcap_path=tmp_path / "x.mcap", rrd_path=tmp_path / "x.rrd"
    ) as sinks:
        assert sinks[0]._children == [] and os.sched_getaffinity(0) == before
        twin = Twin(config, sinks=sinks)
        twins = os.sched_getaffinity(0)
        cpus = [os.sched_getaffinity(child.process.pid) for child in sinks[0]._children]
        twin.step(20)
    assert os.sched_getaffinity(0) == before
    assert len(twins) == 1 and cpus == [before - twins]


def _thread_nices(pid: int) -> dict[str, int]:
    """Each thread of process `pid` (by name, tid) and its nice value, from /proc."""
    nices = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{tid}/stat") as f:
            stat = f.read()
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        nices[f"{name}/{tid}"] = int(stat.rsplit(")", 1)[1].split()[16])
    return nices


def test_the_view_and_its_sdk_threads_yield_the_core_to_the_mcap_writer(tmp_path):
    """The recorder's main thread (the MCAP writer, which the twin may wait on) keeps this
    process's priority; the Rerun writer's thread, and every thread the Rerun SDK starts from it,
    run at LATER_NICE more."""
    from twin.record.recorder import LATER_NICE

    config = TwinConfig()
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    with open_recorders(
        config, RUN, mcap_path=tmp_path / "x.mcap", rrd_path=tmp_path / "x.rrd"
    ) as sinks:
        twin = Twin(config, sinks=sinks)
        twin.step(100)
        sinks[0]._check_started(("mcap", "rrd"))  # the view has started: its SDK's threads run
        pid = sinks[0]._children[0].process.pid
        nices = _thread_nices(pid)
        twin.close()
    main = nices.pop(next(k for k in nices if k.endswith(f"/{pid}")))
    assert main == mine
    assert len(nices) >= 3 and set(nices.values()) == {mine + LATER_NICE}, nices


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: the recorders share it")
def test_at_the_close_every_thread_of_the_recorder_may_use_every_cpu(tmp_path, monkeypatch):
    """An affinity is a thread's own: at the close the recorder's threads (its main one, the Rerun
    writer's and the Rerun SDK's) are each let onto the twin's CPU too, not its main thread
    alone."""
    from twin.record.process import _Child

    seen = []
    finish = _Child.finish

    def looked_at(self, *args, **kwargs):
        tasks = f"/proc/{self.process.pid}/task"
        seen.append([os.sched_getaffinity(int(tid)) for tid in os.listdir(tasks)])
        return finish(self, *args, **kwargs)

    monkeypatch.setattr(_Child, "finish", looked_at)
    config = TwinConfig()
    before = os.sched_getaffinity(0)
    with open_recorders(
        config, RUN, mcap_path=tmp_path / "x.mcap", rrd_path=tmp_path / "x.rrd"
    ) as sinks:
        twin = Twin(config, sinks=sinks)
        twin.step(2000)
        time.sleep(0.5)  # the Rerun writer has started, with its SDK's threads
    (threads,) = seen
    assert len(threads) >= 3 and all(cpus == before for cpus in threads)


def _record_with_a_slow_view(tmp_path, slowing: str, stepping: str) -> str:
    """Record to x.mcap and x.rrd in a process of its own (a lock would hang this one), with
    `slowing` run first (it patches RerunRecorder, which the recorder forks with) and `stepping`
    driving `twin`; what the script printed."""
    script = textwrap.dedent(f"""
        import time
        from twin.model.config import TwinConfig
        from twin.record import open_recorders
        from twin.record.rerun.writer import RerunRecorder
        from twin.sim.twin import Twin
        {textwrap.indent(textwrap.dedent(slowing), " " * 8).strip()}
        config = TwinConfig()
        with open_recorders(
            config, {RUN!r}, mcap_path={str(tmp_path / "x.mcap")!r},
            rrd_path={str(tmp_path / "x.rrd")!r},
        ) as sinks:
            twin = Twin(config, sinks=sinks)
            {textwrap.indent(textwrap.dedent(stepping), " " * 12).strip()}
            twin.close()
        print(sinks[0].waits)
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "x.rrd").stat().st_size > 0
    return done.stdout


def _slow_start(seconds: float) -> str:
    """Script lines that make RerunRecorder take `seconds` more to start (in the recorder)."""
    return f"""
        start = RerunRecorder.__init__
        def slow(self, *args, **kwargs):
            time.sleep({seconds})
            start(self, *args, **kwargs)
        RerunRecorder.__init__ = slow
    """


# 3000 steps, timed: fewer than the ring holds, so the view's rows cannot hold the twin back
_TIMED_STEPS = """
        t0 = time.perf_counter()
        twin.step(3000)
        print(time.perf_counter() - t0)
    """


def test_a_view_slow_to_start_holds_the_twin_back_without_locking_it(tmp_path):
    """The Rerun writer starts in a thread of the recorder: one slower to start than the twin is
    to fill the ring (4,096 rows) makes the twin wait for it, and the recorder wakes to feed it
    once it has started, with nothing lost."""
    printed = _record_with_a_slow_view(tmp_path, _slow_start(1.0), "twin.step(6000)")
    assert int(printed) >= 1  # the twin waited for the view
    assert len(load(tmp_path / "x.mcap").frames) == 6001


def test_a_view_slow_to_start_does_not_hold_back_the_mcap_file(tmp_path):
    """The Rerun writer starts in a thread of the recorder while the MCAP writer is fed: while the
    view takes 2 s to start, the MCAP writer takes its rows in, so the twin steps on within the
    ring. Before, the recorder's main thread waited out the view's start at its first wake-up:
    the thread's class had given its own event a name threading.Thread uses for itself."""
    printed = _record_with_a_slow_view(tmp_path, _slow_start(2.0), _TIMED_STEPS)
    stepped_s, _waits = printed.split()
    assert float(stepped_s) < 1.5  # the 2 s start did not hold the twin
    assert len(load(tmp_path / "x.mcap").frames) == 3001


def test_a_slow_view_batch_does_not_hold_back_the_mcap_file(tmp_path):
    """The Rerun writer is fed in a thread of its own: while one of its batches takes 2 s, the MCAP
    writer goes on taking rows in, so the twin (kept within 0.4 s of simulated time of the MCAP
    file's flushes) steps on; before, the twin waited out the batch. Both files are whole."""
    slowing = """
        take = RerunRecorder.on_frames
        def slow(self, frames):
            if not getattr(self, "slowed", False):
                self.slowed = True
                time.sleep(2.0)
            take(self, frames)
        RerunRecorder.on_frames = slow
    """
    stepping = """
        twin.step(200)
        time.sleep(0.5)  # the view has started: its first take comes at 1,024 rows
    """ + _TIMED_STEPS
    stepped_s, _waits = _record_with_a_slow_view(tmp_path, slowing, stepping).split()
    assert float(stepped_s) < 1.0  # the 2 s batch did not hold the twin
    assert len(load(tmp_path / "x.mcap").frames) == 3201


def test_a_view_writer_error_in_its_thread_is_one_line_and_the_mcap_file_is_whole(tmp_path):
    """The Rerun writer fails in its own thread (a full disk, say): the close says so in one line,
    the MCAP file is finalized with every frame, and the view is left as NAME.partial."""
    script = textwrap.dedent(f"""
        import time
        from twin.model.config import TwinConfig
        from twin.model.errors import RecordingError
        from twin.record import open_recorders
        from twin.record.rerun.writer import RerunRecorder
        from twin.sim.twin import Twin
        take = RerunRecorder.on_frames
        def failing(self, frames):
            self.takes = getattr(self, "takes", 0) + 1
            if self.takes == 2:
                raise OSError(28, "No space left on device")
            take(self, frames)
        RerunRecorder.on_frames = failing  # forked into the recorder with it
        config = TwinConfig()
        try:
            with open_recorders(
                config, {RUN!r}, mcap_path={str(tmp_path / "x.mcap")!r},
                rrd_path={str(tmp_path / "x.rrd")!r},
            ) as sinks:
                twin = Twin(config, sinks=sinks)
                twin.step(1100)
                # the view's first take (1,024 rows) is in before the rest: a view slow to start
                # would otherwise take every row at the close, in one call
                deadline = time.monotonic() + 30
                while sinks[0]._ring.read(1) < 1024 and time.monotonic() < deadline:
                    time.sleep(0.01)
                twin.step(1900)
                twin.close()
        except RecordingError as err:
            print(err)
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    said = done.stdout.strip()
    assert "\n" not in said and "No space left on device" in said, said
    rec = load(tmp_path / "x.mcap")
    assert rec.finalized and len(rec.frames) == 3001
    assert not (tmp_path / "x.rrd").exists()
    assert partial_path(tmp_path / "x.rrd").exists()


def test_a_twin_killed_holding_the_rings_lock_does_not_hang_its_recorder(tmp_path):
    """A kill -9 can land inside a publish, while the twin holds the ring's lock: the recorder,
    seeing the pipe close, goes on without the lock (nobody else writes now), keeps what came and
    exits. It holds the run's stdout, so a recorder waiting on the lock for good would keep
    `subprocess.run` waiting too."""
    path = tmp_path / "x.mcap"
    script = textwrap.dedent(f"""
        import os, signal
        from twin.model.config import TwinConfig
        from twin.record import open_recorders
        from twin.sim.twin import Twin
        config = TwinConfig()
        with open_recorders(config, {RUN!r}, mcap_path={str(path)!r}) as sinks:
            twin = Twin(config, sinks=sinks)
            twin.step(1000)
            sinks[0]._ring._lock.acquire()  # as inside a publish
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    fixed = tmp_path / "fixed.mcap"
    recover(partial_path(path), fixed)
    assert len(load(fixed).frames) > 500


def _children() -> dict[int, str]:
    """This process's children and their state letters from /proc ("Z": exited, not reaped)."""
    children = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if int(fields[1]) == os.getpid():
            children[int(entry)] = fields[0]
    return children


def _record_briefly(path) -> None:
    config = TwinConfig()
    with open_recorders(config, RUN, mcap_path=path) as sinks:
        twin = Twin(config, sinks=sinks)
        twin.step(100)
        twin.close()
    assert load(path).finalized


def test_finished_recorder_processes_are_reaped_by_the_next_recording(tmp_path):
    """The close does not wait for the recorder process's exit: the next recording's start reaps
    every recorder that has exited by then, so finished ones do not pile up as zombies."""
    before = set(_children())
    for i in range(3):
        _record_briefly(tmp_path / f"{i}.mcap")
    deadline = time.monotonic() + 30
    while True:  # until every recorder of ours has exited (one still running cannot be reaped)
        ours = {pid: state for pid, state in _children().items() if pid not in before}
        if all(state == "Z" for state in ours.values()) or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    exited = {pid for pid, state in ours.items() if state == "Z"}
    assert exited, "the last recording's recorder should be left for the next start to reap"
    _record_briefly(tmp_path / "next.mcap")
    assert not exited & set(_children())


def test_commands_events_and_pictures_cross_to_the_recorder_unchanged():
    """What the twin sends besides rows travels as its fields' values (recorder.pack_other) and is
    rebuilt as the same item, of the same class, whatever its data holds."""
    from twin.model.images import CameraImage
    from twin.model.types import Command, Event
    from twin.record.recorder import COMMAND, EVENT, IMAGE, pack_other, unpack_other

    items = {
        COMMAND: Command(12, "joint_target", {"joint": 1, "q": 0.5}),
        EVENT: Event(7, 29_166_666, "note", "box", "odd", {"v": np.float32(1.5), "b": b"\x00"}),
        IMAGE: CameraImage("pad", 3, 12_500_000, "png", b"\x89PNG", (1.0, 2.0, 3.0, 0, 0, 0, 1)),
    }
    for kind, item in items.items():
        back = unpack_other(kind, pack_other(kind, item))
        assert type(back) is type(item) and back == item


def test_the_byte_that_says_the_rerun_writer_started_is_taken_as_soon_as_it_comes():
    """Woken by the byte the Rerun writer's thread writes once the writer has started, the
    recorder's main loop takes it and replies at once, whatever else that thread has yet to do. It
    used to read the byte only once a flag, set just after it, said so: woken in between (the
    thread niced, on the same core), the loop left the byte unread and woke again at once, over and
    over (CHANGES.md has the figures)."""
    import multiprocessing
    import select

    from twin.record.recorder import _Later

    later = _Later([], make=None)  # no thread: the test is that thread, just after its byte
    later.replied = False
    ours, _theirs = multiprocessing.Pipe()
    try:
        later.reply(ours, [], wait=False)  # woken by something else: nothing to take yet
        assert not later.replied
        os.write(later._done_w, b"S")
        later.reply(ours, [], wait=False)  # as the main loop does, woken by the byte
        assert not select.select([later.done_fd], [], [], 0)[0], "the byte was left unread"
        assert later.replied
    finally:
        os.close(later.done_fd)
        os.close(later._done_w)
