"""Benchmark section: what recording costs.

pick_place run without recording, with MCAP, with MCAP + Rerun, each as a ratio to the
physics-only step rate; MCAP bytes per simulated minute; the recorder's cost per step; load time.
And against what a user would pick instead: the reads floor (the same motion with a Frame's engine
reads and nothing else) and a hand-written logger (rr.log of the joints and the box plus one JSON
MCAP message a step): `record_both_vs_reads`, `record_both_vs_naive`.
tools/bench.py calls bench(ctx); `python tools/bench_record.py` runs it alone.

Each run is timed twice over: its stepping (first Frame to last, what the physics-only baseline
times too: `record_*_vs_motion`) and the whole run (recorders started, twin built, stepping, files
finalized: `record_*_run_vs_motion`), with the start and finish costs on their own rows. The modes
take turns, repeat by repeat, so a machine that slows down slows them all; and each repeat first
takes its own sample of the same motion's physics-only baseline
(bench.pick_place_physics_steps_per_s), so a `record_*_vs_motion` ratio is the median of each
repeat's rate over the baseline measured beside it. (On this shared machine the baseline alone moved
from 34k to 56k steps/s within one minute: a ratio to a baseline taken a minute earlier measured the
machine as much as the recorder.)
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

from twin.model.config import TwinConfig
from twin.model.sink import Sink
from twin.record import open_recorders
from twin.record.mcap.reader import load
from twin.record.mcap.writer import FLUSH_S
from twin.record.process import RRD_TAKE_S
from twin.record.rows import FrameRows
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run alone: bench.py beside this file
from bench import motion_actions, pick_place_physics_steps_per_s, replay_motion

CYCLES = 16
RUN = {"source": "task", "task": "pick_place", "params": {"cycles": CYCLES}}


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the recorder process)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


class _Clock(Sink):
    """A sink after the recorders: the wall time of the first and the last Frame."""

    reads_pad_pose = False  # only the time: a twin with no recorder leaves the pad pose out

    def __init__(self) -> None:
        self.first_s = self.last_s = 0.0

    def on_frame(self, frame) -> None:
        self.last_s = time.perf_counter()
        if frame.step == 0:
            self.first_s = self.last_s


class Timed(NamedTuple):
    steps: int
    stepping_s: float  # first Frame to last
    run_s: float  # open_recorders to files finalized
    start_s: float  # open_recorders to the first Frame (recorders started, twin built)
    finish_s: float  # last Frame to files finalized
    cpu_s: float  # this process's threads and the recorder process it waited for
    mcap_bytes: int
    waits: int  # how often the twin waited for a recorder to catch up
    stepping_cpu_s: float = 0.0  # this process alone (the stepping one), the whole run
    recorders: object = None  # the recorder process's RecorderStats (record.recorder)


def timed_run(folder: Path, *, mcap: bool, rrd: bool, cycles: int = CYCLES) -> Timed:
    """One pick_place run, timed (see the module docstring)."""
    config = TwinConfig()
    mcap_path = folder / "bench.mcap" if mcap else None
    rrd_path = folder / "bench.rrd" if rrd else None
    clock = _Clock()
    run = {**RUN, "params": {"cycles": cycles}}
    t0, cpu0, own0 = time.perf_counter(), _cpu_s(), time.process_time()
    with open_recorders(config, run, mcap_path=mcap_path, rrd_path=rrd_path) as sinks:
        twin = Twin(config, sinks=[*sinks, clock])
        run_task(twin, TASKS["pick_place"], {"cycles": cycles})
        twin.close()
        waits = sum(getattr(sink, "waits", 0) for sink in sinks)
    t1, cpu_s, own_s = time.perf_counter(), _cpu_s() - cpu0, time.process_time() - own0
    recorders = next((s.stats for s in sinks if getattr(s, "stats", None) is not None), None)
    return Timed(
        twin.step_index,
        clock.last_s - clock.first_s,
        t1 - t0,
        clock.first_s - t0,
        t1 - clock.last_s,
        cpu_s,
        mcap_path.stat().st_size if mcap_path else 0,
        waits,
        own_s,
        recorders,
    )


def packed_run() -> tuple[TwinConfig, FrameRows, bytearray, list]:
    """pick_place's 16-cycle run as its recorder processes get it: (config, row layout, the rows
    packed one after another, its events)."""
    from twin.verify.collectors import FrameCollector

    config = TwinConfig()
    collector = FrameCollector()
    twin = Twin(config, sinks=[collector])
    run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
    twin.close()
    rows = FrameRows(len(config.profile.joint_names), len(config.objects))
    packed = bytearray(len(collector.frames) * rows.size)
    for i, frame in enumerate(collector.frames):
        rows.pack_into(packed, i * rows.size, frame)
    return config, rows, packed, collector.events


def _feeds(n: int, take: int, events: list):
    """(start, end, the events after frame end - 1) in the order a recorder process feeds a writer:
    rows a take at a time, split where an event comes (after the frame of its step)."""
    cuts = sorted({*range(take, n, take), n, *(min(n, e.step + 1) for e in events)})
    start, at = 0, 0
    for end in cuts:
        before = []
        while at < len(events) and min(n, events[at].step + 1) <= end:
            before.append(events[at])
            at += 1
        yield start, end, before
        start = end


def recorder_cpu_us_per_frame(
    folder: Path,
    repeats: int,
    run: tuple,
    writer: str = "mcap",
    *,
    take: int = 0,
    nap_s: float = 0.0,
) -> float:
    """Process CPU time (all its threads) a writer ("mcap" or "rrd") spends per frame, fed `run`
    (packed_run) as its recorder process feeds it: packed rows, `take` at a time (by default a
    flush's worth: the recorder is woken just after each MCAP flush frame, 120 frames at 240 Hz)
    split where an event comes; no physics. Back to back, or asleep `nap_s` before each take, as
    the recorder sleeps between the twin's wake-ups (the sleep is not CPU time)."""
    from twin.robot.urdf import urdf_text

    config, rows, packed, events = run
    n = rows.count(packed)
    if writer == "mcap":
        from twin.record.mcap.writer import McapRecorder

        def make():
            return McapRecorder(folder / "cpu.mcap", config, RUN, urdf=urdf_text(config.profile))
    else:
        from twin.record.rerun.writer import RerunRecorder

        def make():
            return RerunRecorder(folder / "cpu.rrd", config, urdf_text(config.profile))

    spent = []
    for _ in range(max(3, repeats)):
        recorder = make()  # the start (static scene, meshes) is not per frame
        t0 = time.process_time()
        every = take or _flush_frames(config)
        for start, end, before in _feeds(n, every, events):
            if nap_s and start % every == 0:  # a take's first rows (an event splits takes)
                time.sleep(nap_s)
            recorder.on_frames(
                rows.columns(memoryview(packed)[start * rows.size : end * rows.size], copy=False)
            )
            for event in before:
                recorder.on_event(event)
        recorder.close()
        spent.append(time.process_time() - t0)
    # the median, as the recorder's own figure is: a best against a median would widen the gap
    return statistics.median(spent) / n * 1e6


def reads_floor_steps_per_s(cycles: int = 2, clock=time.perf_counter) -> float:
    """The reads floor: pick_place's motion on the bare World (as the motion baseline) plus, every
    step, the engine reads a Frame is made of (World.state) and nothing else: the most any logger
    that records what a Frame holds can reach. Timed by `clock` (wall time unless told)."""
    from twin.sim.world import World

    n_steps, actions = motion_actions(cycles)
    world = World(TwinConfig())
    try:
        t0 = clock()
        replay_motion(world, n_steps, actions, lambda step: world.state())
        return n_steps / (clock() - t0)
    finally:
        world.close()


def naive_logger_steps_per_s(folder: Path, cycles: int = 2) -> float:
    """What a user writes without twin: the same motion, and every step its reads, an rr.log of the
    joints and of the box, and one JSON message in an MCAP file. Stepping timed, as the twin's is
    (the files' finish excluded)."""
    import json

    import rerun as rr
    from mcap.writer import Writer

    from twin.sim.world import World

    n_steps, actions = motion_actions(cycles)
    config = TwinConfig()
    world = World(config)
    stream = rr.RecordingStream("twin_bench_naive")
    stream.save(folder / "naive.rrd")
    with open(folder / "naive.mcap", "wb") as f:
        writer = Writer(f)
        writer.start()
        schema = writer.register_schema("state", "jsonschema", b'{"type": "object"}')
        channel = writer.register_channel("/state", "json", schema)

        def log(step: int) -> None:
            q, _, _, poses, _, _ = world.state()
            box = poses[0]
            t_ns = step * config.dt_ns
            stream.set_time("step", sequence=step)
            stream.log("joints", rr.Scalars(q))
            stream.log(
                "box", rr.Transform3D(translation=box[:3], quaternion=rr.Quaternion(xyzw=box[3:7]))
            )
            writer.add_message(
                channel,
                log_time=t_ns,
                publish_time=t_ns,
                data=json.dumps({"step": step, "q": q, "box": box}).encode(),
            )

        try:
            t0 = time.perf_counter()
            replay_motion(world, n_steps, actions, log)
            rate = n_steps / (time.perf_counter() - t0)
        finally:
            writer.finish()
            stream.flush()
            world.close()
    return rate


def _have_rerun_writer() -> bool:
    try:
        import twin.record.rerun.writer  # noqa: F401
    except ImportError:
        return False
    return True


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(1, int(ctx.repeats))
    modes = {"twin, no recording": (False, False), "twin + MCAP": (True, False)}
    if _have_rerun_writer():
        modes["twin + MCAP + Rerun"] = (True, True)
    rows: list[tuple[str, str]] = []
    rates: dict[str, float] = {}
    cpu_us: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="twin_bench_record_") as tmp:
        folder = Path(tmp)
        runs: dict[str, list[Timed]] = {name: [] for name in modes}
        # each repeat's own physics-only baseline, taken just before its modes
        motion: list[float] = []
        reads: list[float] = []  # and the reads floor and the hand-written logger, beside it
        naive: list[float] = []
        # the reads floor over the same cycles, just before and just after each run with both
        # files (their mean): what record_both_vs_reads divides by
        bracket: list[float] = []
        for _ in range(repeats):  # the modes take turns
            motion.append(pick_place_physics_steps_per_s())
            reads.append(reads_floor_steps_per_s())
            if "twin + MCAP + Rerun" in modes:
                naive.append(naive_logger_steps_per_s(folder))
            for name, (mcap, rrd) in modes.items():
                both = name == "twin + MCAP + Rerun"
                before = reads_floor_steps_per_s(CYCLES) if both else 0.0
                runs[name].append(timed_run(folder, mcap=mcap, rrd=rrd))
                if both:
                    bracket.append((before + reads_floor_steps_per_s(CYCLES)) / 2)
        ctx.figures["record_motion_steps_per_s"] = statistics.median(motion)
        rows.append(
            (
                (
                    f"physics-only steps/s of the same motion, taken beside each repeat "
                    f"(median of {repeats})"
                ),
                f"{statistics.median(motion):,.0f} ({min(motion):,.0f} .. {max(motion):,.0f})",
            )
        )

        def paired(name: str, rates_by_repeat: list[float]) -> None:
            """NAME_steps_per_s, NAME_vs_idle (to the run's idle baseline) and NAME_vs_motion (the
            median of the repeats' ratios to the baseline taken beside them) for --json."""
            ctx.rate_figures(name, statistics.median(rates_by_repeat))
            ctx.figures[f"{name}_vs_motion"] = statistics.median(
                r / m for r, m in zip(rates_by_repeat, motion, strict=True)
            )

        steps = runs["twin, no recording"][0].steps
        mcap_bytes = runs["twin + MCAP"][-1].mcap_bytes
        for name, timed in runs.items():
            stepping = [t.steps / t.stepping_s for t in timed]
            whole = [t.steps / t.run_s for t in timed]
            rates[name] = statistics.median(stepping)
            cpu_us[name] = statistics.median(t.cpu_s / t.steps * 1e6 for t in timed)
            key = {
                "twin, no recording": "record_none",
                "twin + MCAP": "record_mcap",
                "twin + MCAP + Rerun": "record_both",
            }[name]
            paired(key, stepping)
            paired(f"{key}_run", whole)
            rows.append(
                (
                    f"{name}: stepping steps/s (ratio: idle; same motion, paired)",
                    f"{_rate_text(ctx, key)}; CPU {cpu_us[name]:.1f} us/step (whole run)",
                )
            )
            start_ms = statistics.median(t.start_s for t in timed) * 1e3
            finish_ms = statistics.median(t.finish_s for t in timed) * 1e3
            waits = statistics.median(t.waits for t in timed)
            rows.append(
                (
                    f"{name}: whole run, start and finish included",
                    f"{_rate_text(ctx, key + '_run')}; start {start_ms:.0f} ms, finish "
                    f"{finish_ms:.0f} ms"
                    + (
                        f"; the twin waited for a recorder {waits:.0f} times a run"
                        if key != "record_none"
                        else ""
                    ),
                )
            )
            if key != "record_none":
                ctx.figures[f"{key}_start_ms"] = start_ms
                ctx.figures[f"{key}_finish_ms"] = finish_ms
        plain, with_mcap = rates["twin, no recording"], rates["twin + MCAP"]
        rows.append(
            (
                "twin + MCAP: speed relative to no recording (wall; CPU)",
                (
                    f"{with_mcap / plain:.2f}x; "
                    f"{cpu_us['twin, no recording'] / cpu_us['twin + MCAP']:.2f}x"
                ),
            )
        )
        rows.append(
            (
                "MCAP recorder cost per step (wall, in the run)",
                f"{(1 / with_mcap - 1 / plain) * 1e6:.2f} us",
            )
        )
        if "twin + MCAP + Rerun" in rates:
            both = rates["twin + MCAP + Rerun"]
            rows.append(
                (
                    "twin + MCAP + Rerun: speed relative to no recording (wall; CPU)",
                    (
                        f"{both / plain:.2f}x; "
                        f"{cpu_us['twin, no recording'] / cpu_us['twin + MCAP + Rerun']:.2f}x"
                    ),
                )
            )
            rows.append(
                (
                    "MCAP + Rerun recorders cost per step (wall, in the run)",
                    f"{(1 / both - 1 / plain) * 1e6:.2f} us",
                )
            )
        rows.extend(_user_baselines(ctx, runs, motion, (reads, bracket), naive))
        run = packed_run()  # one run fed to each writer
        for writer, label in (("mcap", "MCAP"), ("rrd", "Rerun")):
            if writer == "rrd" and "twin + MCAP + Rerun" not in rates:
                continue
            cpu = recorder_cpu_us_per_frame(folder, repeats, run, writer)
            ctx.figures[f"record_{writer}_writer_cpu_us_per_frame"] = cpu
            rows.append(
                (
                    f"{label} writer CPU per frame (its process, isolated, median of repeats)",
                    f"{cpu:.2f} us",
                )
            )
        if "twin + MCAP + Rerun" in rates:
            rows.extend(long_runs(ctx, folder, repeats, run))
        sim_min = steps * TwinConfig().dt_ns * 1e-9 / 60.0
        rows.append(("MCAP bytes per simulated minute", f"{mcap_bytes / sim_min / 1e6:.2f} MB"))
        ctx.figures["mcap_mb_per_sim_min"] = mcap_bytes / sim_min / 1e6
        t0 = time.perf_counter()
        recording = load(folder / "bench.mcap")
        load_s = time.perf_counter() - t0
        rows.append(
            (
                "load() per simulated minute",
                f"{load_s / sim_min * 1000:.1f} ms ({len(recording.frames)} frames)",
            )
        )
    return rows


def _flush_frames(config: TwinConfig) -> int:
    """Frames between two of the MCAP writer's flushes: the recorder's wake-ups."""
    return round(FLUSH_S * 1e9 / config.dt_ns)


def long_runs(ctx, folder: Path, repeats: int, run: tuple) -> list[tuple[str, str]]:
    """pick_place's long run (ctx.long_cycles cycles, 100 by default: 109,876 steps, where a
    recorder's cost per frame shows as a short run hides it) without recording and with both files,
    taking turns: the stepping speed with both over without (record_both_long_vs_none, paired by
    repeat), the CPU per step of the stepping process in each (record_cpu_us_per_step_none, _both),
    and each recorder process's CPU per frame and its writer's share of it, against the isolated
    writers (record_recorders_cpu_us_per_frame, record_writers_cpu_us_per_frame)."""
    none, both = [], []
    folder = folder / "long"  # beside the short runs' files, which the section loads afterwards
    folder.mkdir(exist_ok=True)
    for _ in range(repeats):
        none.append(timed_run(folder, mcap=False, rrd=False, cycles=ctx.long_cycles))
        both.append(timed_run(folder, mcap=True, rrd=True, cycles=ctx.long_cycles))
    steps = none[0].steps
    f = ctx.figures
    f["record_both_long_vs_none"] = statistics.median(
        n.stepping_s / b.stepping_s for n, b in zip(none, both, strict=True)
    )
    f["record_cpu_us_per_step_none"] = (
        statistics.median(t.stepping_cpu_s for t in none) / steps * 1e6
    )
    f["record_cpu_us_per_step_both"] = (
        statistics.median(t.stepping_cpu_s for t in both) / steps * 1e6
    )
    f["record_recorders_cpu_us_per_frame"] = (
        statistics.median(t.recorders.cpu_s for t in both) / steps * 1e6
    )
    f["record_recorders_writer_cpu_us_per_frame"] = (
        statistics.median(t.recorders.writer_cpu_s for t in both) / steps * 1e6
    )
    by_writer = {
        writer: statistics.median(dict(t.recorders.by_writer)[writer] for t in both) / steps * 1e6
        for writer, _ in both[0].recorders.by_writer
    }
    f["record_writers_cpu_us_per_frame"] = (
        f["record_mcap_writer_cpu_us_per_frame"] + f["record_rrd_writer_cpu_us_per_frame"]
    )
    # the same writers fed at the long run's pace: asleep, between takes, as long as the twin took
    # to step that many frames (the MCAP writer every flush, the Rerun writer every RRD_TAKE_S)
    frame_s = statistics.median(t.stepping_s for t in both) / steps
    config = run[0]
    paces = {"mcap": _flush_frames(config), "rrd": round(RRD_TAKE_S * 1e9 / config.dt_ns)}
    f["record_writers_paced_cpu_us_per_frame"] = sum(
        recorder_cpu_us_per_frame(folder, repeats, run, w, take=take, nap_s=take * frame_s)
        for w, take in paces.items()
    )
    rows = [
        (
            f"long run ({steps:,} steps): stepping with MCAP + Rerun over without (paired)",
            f"{f['record_both_long_vs_none']:.2f}x",
        ),
        (
            "long run: stepping process CPU per step, no recording; MCAP + Rerun",
            (
                f"{f['record_cpu_us_per_step_none']:.1f} us; "
                f"{f['record_cpu_us_per_step_both']:.1f} us"
            ),
        ),
    ]
    cpu = f["record_recorders_cpu_us_per_frame"]
    in_writers = f["record_recorders_writer_cpu_us_per_frame"]
    rows.append(
        (
            "long run: recorder process CPU per frame (its writers: "
            + ", ".join(by_writer)
            + "; around them)",
            f"{cpu:.2f} us ("
            + ", ".join(f"{us:.2f}" for us in by_writer.values())
            + f"; {cpu - in_writers:.2f})",
        )
    )
    rows.append(
        (
            (
                "long run: recorder CPU per frame; the isolated writers, summed (back to back; "
                "asleep between takes as in the run)"
            ),
            (
                f"{f['record_recorders_cpu_us_per_frame']:.2f} us; "
                f"{f['record_writers_cpu_us_per_frame']:.2f} us "
                f"({f['record_writers_paced_cpu_us_per_frame']:.2f} us)"
            ),
        )
    )
    return rows


def _user_baselines(
    ctx, runs: dict[str, list[Timed]], motion: list[float], reads: tuple, naive: list[float]
) -> list[tuple[str, str]]:
    """The reads floor and the hand-written logger, each paired repeat by repeat with the motion
    baseline and with twin + MCAP + Rerun: record_both_vs_reads, record_both_vs_naive for --json.
    reads: (the floor taken beside the motion baseline, the floor over the same cycles bracketing
    each run with both files); record_both_vs_reads divides by the second: runs seconds apart on a
    shared machine differ by more than the figure's margin."""
    reads, bracket = reads

    def paired(a: list[float], b: list[float]) -> float:
        return statistics.median(x / y for x, y in zip(a, b, strict=True))

    ctx.figures["record_reads_steps_per_s"] = statistics.median(reads)
    ctx.figures["record_reads_vs_motion"] = paired(reads, motion)
    rows = [
        (
            "the reads floor: the same motion, a Frame's engine reads and nothing else (steps/s)",
            (
                f"{statistics.median(reads):,.0f} "
                f"({ctx.figures['record_reads_vs_motion']:.2f}x same motion)"
            ),
        )
    ]
    if not naive:
        return rows
    both = [t.steps / t.stepping_s for t in runs["twin + MCAP + Rerun"]]
    ctx.figures["record_naive_steps_per_s"] = statistics.median(naive)
    ctx.figures["record_naive_vs_motion"] = paired(naive, motion)
    ctx.figures["record_reads_beside_both_steps_per_s"] = statistics.median(bracket)
    ctx.figures["record_both_vs_reads"] = paired(both, bracket)
    ctx.figures["record_both_vs_naive"] = paired(both, naive)
    rows.append(
        (
            (
                "a hand-written logger: rr.log of joints and box + one JSON MCAP message a "
                "step (steps/s)"
            ),
            (
                f"{statistics.median(naive):,.0f} "
                f"({ctx.figures['record_naive_vs_motion']:.2f}x same motion)"
            ),
        )
    )
    rows.append(
        (
            (
                "twin + MCAP + Rerun against the reads floor (the same cycles, just before and "
                "after); against the hand-written logger"
            ),
            (
                f"{ctx.figures['record_both_vs_reads']:.2f}x; "
                f"{ctx.figures['record_both_vs_naive']:.2f}x"
            ),
        )
    )
    return rows


def _rate_text(ctx, key: str) -> str:
    """'31,250 (0.45x idle, 0.78x same motion)' from the figures paired() wrote."""
    f = ctx.figures
    return (
        f"{f[key + '_steps_per_s']:,.0f} ({f[key + '_vs_idle']:.2f}x idle, "
        f"{f[key + '_vs_motion']:.2f}x same motion)"
    )


def main() -> int:
    """Run this section alone, with bench.py's baselines."""
    from bench import main as bench_main

    return bench_main(["--only", "record"])


if __name__ == "__main__":
    sys.exit(main())
