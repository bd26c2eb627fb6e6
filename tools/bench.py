"""The benchmark entry point: `python tools/bench.py [--only NAME ...] [--repeats N]`.

It first measures two physics-only baselines as medians over repeats: the idle scene (floor + the
mtb robot + a box, stepSimulation alone, DIRECT mode, 240 Hz, through twin.world.World), and the
same physics doing pick_place's work (the task's motor targets and holds applied straight to the
World at their steps, stepSimulation alone: no Frames, no suction rule, no sinks). A moving arm
with contacts costs about twice an idle one, so the second is the fair yardstick for the twin's
own overhead on that task. Then it runs the sections:
every tools/bench_*.py, sorted by name, each defining `bench(ctx) -> list[tuple[str, str]]` of
(label, value) rows. It prints one table; every ratio in it is measured in this one run.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import os
import platform
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
PHYSICS_STEPS = 20_000
WARMUP_STEPS = 200
DT_S = 1.0 / 240.0


@dataclass(frozen=True)
class BenchContext:
    """What every section gets: the baseline, how often to repeat, and a timing helper."""

    physics_steps_per_s: float  # median over repeats, idle scene
    physics_samples: tuple[float, ...]  # each repeat's steps/s
    repeats: int
    # median over repeats, pick_place's motion (0: not measured)
    motion_physics_steps_per_s: float = 0.0
    # pick_place cycles of the record section's long run (its figures need about 100)
    long_cycles: int = 100
    physics_step_us: float = field(init=False)
    # named numbers for --json (sections add theirs)
    figures: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "physics_step_us", 1e6 / self.physics_steps_per_s)

    def median_rate(self, run: Callable[[], int]) -> float:
        """Median over `repeats` of count / wall seconds, where `run()` does the work and returns
        the count."""
        samples = []
        for _ in range(self.repeats):
            t0 = time.perf_counter()
            count = run()
            samples.append(count / (time.perf_counter() - t0))
        return statistics.median(samples)

    def rate_figures(self, name: str, steps_per_s: float) -> None:
        """NAME_steps_per_s and its ratios to both baselines (NAME_vs_idle, NAME_vs_motion) for
        --json."""
        self.figures[f"{name}_steps_per_s"] = steps_per_s
        self.figures[f"{name}_vs_idle"] = steps_per_s / self.physics_steps_per_s
        if self.motion_physics_steps_per_s:
            self.figures[f"{name}_vs_motion"] = steps_per_s / self.motion_physics_steps_per_s

    def ratio(self, steps_per_s: float) -> str:
        """A step rate with its ratios to both physics-only baselines, e.g. '31,250 (0.45x idle,
        0.78x motion)'."""
        text = f"{steps_per_s:,.0f} ({steps_per_s / self.physics_steps_per_s:.2f}x idle"
        if self.motion_physics_steps_per_s:
            text += f", {steps_per_s / self.motion_physics_steps_per_s:.2f}x same motion"
        return text + ")"


def physics_only_steps_per_s(steps: int = PHYSICS_STEPS) -> float:
    """One sample of the bare PyBullet loop: the default twin scene, stepSimulation only."""
    from twin.model.config import TwinConfig
    from twin.sim.world import World

    world = World(TwinConfig())
    try:
        for _ in range(WARMUP_STEPS):
            world.step()
        t0 = time.perf_counter()
        for _ in range(steps):
            world.step()
        return steps / (time.perf_counter() - t0)
    finally:
        world.close()


# the run is deterministic: every baseline sample of a bench run replays the same motion
@functools.cache
def motion_actions(cycles: int = 2) -> tuple[int, dict[int, list[tuple]]]:
    """pick_place's steps and, by step, what the bare World must do to repeat its motion: the motor
    targets it set and the holds it made and ended (from one twin run; read it, do not change
    it)."""
    from twin.sim.twin import Twin
    from twin.tasks import TASKS
    from twin.verify.collectors import FrameCollector

    collector = FrameCollector()
    twin = Twin(sinks=[collector])
    TASKS["pick_place"](twin, cycles=cycles)
    n_steps, profile = twin.step_index, twin.profile
    twin.close()
    actions: dict[int, list[tuple]] = {}
    for c in collector.commands:  # commands first: the twin applies them before its suction rule
        if c.kind == "joint_target":
            actions.setdefault(c.step, []).append(
                ("motor", profile.joint_index(c.args["joint"]), c.args["q"])
            )
    for e in collector.events:
        if e.kind == "attach":
            f = collector.frames[e.step]
            root = (f.pad_pose[0], f.pad_pose[1], f.pad_pose[2] + profile.pad_length_m)
            yaw = f.joint_q[0] + f.joint_q[1] + f.joint_q[3]
            actions.setdefault(e.step, []).append(("attach", 0, root, yaw))
        elif e.kind in ("release", "break"):
            actions.setdefault(e.step, []).append(("detach",))
    return n_steps, actions


def replay_motion(
    world,
    n_steps: int,
    actions: dict[int, list[tuple]],
    after_step: Callable[[int], None] | None = None,
) -> None:
    """Step the bare World through a motion from motion_actions; after_step(step) after each step
    (a baseline's own work: reading the state, logging it)."""
    v_max = world.max_velocities()
    for step in range(n_steps):
        for action in actions.get(step, ()):
            if action[0] == "motor":
                world.set_motor(action[1], action[2], v_max[action[1]])
            elif action[0] == "attach":
                world.attach(action[1], action[2], action[3])
            else:
                world.detach()
        world.step()
        if after_step is not None:
            after_step(step + 1)


def pick_place_physics_steps_per_s(cycles: int = 2) -> float:
    """One sample of the bare PyBullet loop doing pick_place's work (see the module docstring)."""
    from twin.model.config import TwinConfig
    from twin.sim.world import World

    n_steps, actions = motion_actions(cycles)
    world = World(TwinConfig())
    try:
        t0 = time.perf_counter()
        replay_motion(world, n_steps, actions)
        return n_steps / (time.perf_counter() - t0)
    finally:
        world.close()


def discover() -> dict[str, Path]:
    """Section name (the part after bench_) -> module path, sorted by name."""
    return {p.stem.removeprefix("bench_"): p for p in sorted(TOOLS.glob("bench_*.py"))}


def _load(path: Path):
    if str(TOOLS) not in sys.path:
        sys.path.insert(0, str(TOOLS))  # sections may import one another or this module
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    fn = getattr(module, "bench", None)
    if not callable(fn):
        raise TypeError(f"{path.name} defines no bench(ctx)")
    return fn


def _table(rows: list[tuple[str, str, str]]) -> list[str]:
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    rule = "-" * (w0 + w1 + 6 + max(len(r[2]) for r in rows))
    lines = [rule]
    for i, (section, label, value) in enumerate(rows):
        lines.append(f"{section:<{w0}} | {label:<{w1}} | {value}")
        if i == 0:
            lines.append(rule)
    lines.append(rule)
    return lines


def run(
    only: list[str],
    repeats: int,
    physics_steps: int = PHYSICS_STEPS,
    json_path: str | None = None,
    long_cycles: int = 100,
) -> int:
    sections = discover()
    unknown = sorted(set(only) - set(sections))
    if unknown:
        print(
            f"bench: error: unknown section {unknown[0]!r}; expected one of {', '.join(sections)}",
            file=sys.stderr,
        )
        return 2
    chosen = {name: path for name, path in sections.items() if not only or name in only}
    from twin.sim.world import pybullet_version

    load_before = os.getloadavg()
    t_start = time.perf_counter()
    samples = tuple(physics_only_steps_per_s(physics_steps) for _ in range(repeats))
    motion = tuple(pick_place_physics_steps_per_s() for _ in range(repeats))
    ctx = BenchContext(
        physics_steps_per_s=statistics.median(samples),
        physics_samples=samples,
        repeats=repeats,
        motion_physics_steps_per_s=statistics.median(motion),
        long_cycles=long_cycles,
    )
    ctx.figures.update(
        physics_steps_per_s=ctx.physics_steps_per_s,
        motion_physics_steps_per_s=ctx.motion_physics_steps_per_s,
    )
    realtime = ctx.physics_steps_per_s * DT_S
    rows = [
        ("section", "measure", "value"),
        (
            "machine",
            "python / pybullet API / cpus",
            f"{platform.python_version()} / {pybullet_version()} / {os.cpu_count()}",
        ),
        (
            "physics",
            f"physics-only steps/s (median of {repeats})",
            (
                f"{ctx.physics_steps_per_s:,.0f} ({ctx.physics_step_us:.1f} us/step, "
                f"{realtime:.0f}x real time at 240 Hz)"
            ),
        ),
        ("physics", "spread over repeats", f"{min(samples):,.0f} .. {max(samples):,.0f}"),
        (
            "physics",
            "physics-only steps/s, pick_place's motion and holds (median)",
            (
                f"{ctx.motion_physics_steps_per_s:,.0f} "
                f"({1e6 / ctx.motion_physics_steps_per_s:.1f} us/step)"
            ),
        ),
    ]
    failed = 0
    for name, path in chosen.items():
        t0 = time.perf_counter()
        try:
            section_rows = _load(path)(ctx)
        except Exception as err:  # noqa: BLE001 - a broken section is reported in the table; the others run
            failed += 1
            rows.append((name, "FAILED", f"{type(err).__name__}: {err}"))
            traceback.print_exc(file=sys.stderr)
            continue
        rows.extend((name, str(label), str(value)) for label, value in section_rows)
        rows.append((name, "section wall time", f"{time.perf_counter() - t0:.1f} s"))
    rows.append(("total", "wall time", f"{time.perf_counter() - t_start:.1f} s"))
    print("\n".join(_table(rows)))
    if json_path:
        write_json(json_path, ctx.figures, rows, run_facts(only, repeats, load_before))
    return 1 if failed else 0


def run_facts(only: list[str], repeats: int, load_before: tuple[float, ...]) -> dict:
    """When, where and how the run was made, for the docs' benchmarks page: UTC date, the machine
    (CPU, cores, kernel, Python, PyBullet) and the load average before and after (a busy machine
    gives noisy figures)."""
    import datetime

    from twin.record.machine import machine, machine_text
    from twin.sim.world import pybullet_version

    command = ["python tools/bench.py", *(f"--only {n}" for n in only), f"--repeats {repeats}"]
    return {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "machine": {
            "cpu": machine_text(machine()),
            "cpus": os.cpu_count(),
            "kernel": platform.release(),
            "python": platform.python_version(),
            "pybullet": pybullet_version(),
        },
        "command": " ".join(command),
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }


def write_json(
    path: str,
    figures: dict[str, float],
    rows: list[tuple[str, str, str]],
    facts: dict | None = None,
) -> None:
    """The run as JSON: every named figure at the top level (ratios are plain numbers, e.g.
    record_both_vs_motion), every row of the table under "rows", and the run's date, machine,
    command and load under "run" (tools/docs_benchmarks.py renders it into the docs)."""
    doc = {
        **{k: round(v, 6) for k, v in sorted(figures.items())},
        "rows": [{"section": a, "measure": b, "value": c} for a, b, c in rows[1:]],
    }
    if facts is not None:
        doc["run"] = facts
    Path(path).write_text(json.dumps(doc, indent=2) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="NAME",
        help=f"run only this section (repeatable): {', '.join(discover())}",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="repeats per measurement, median reported (default 3)",
    )
    parser.add_argument(
        "--physics-steps",
        type=int,
        default=PHYSICS_STEPS,
        help=f"steps per physics-only sample (default {PHYSICS_STEPS})",
    )
    parser.add_argument(
        "--long-cycles",
        type=int,
        default=100,
        help="pick_place cycles of the record section's long run (default 100: 109,876 steps; "
        "fewer only to try the bench quickly, its long-run figures then mean little)",
    )
    parser.add_argument("--list", action="store_true", help="list the sections and exit")
    parser.add_argument(
        "--json", metavar="FILE", help="also write every figure of the table to FILE as JSON"
    )
    args = parser.parse_args(argv)
    if args.list:
        print("\n".join(discover()))
        return 0
    if min(args.repeats, args.physics_steps, args.long_cycles) < 1:
        print(
            f"bench: error: --repeats {args.repeats}, --physics-steps {args.physics_steps} and "
            f"--long-cycles {args.long_cycles} must be >= 1",
            file=sys.stderr,
        )
        return 2
    if args.json and not Path(args.json).parent.is_dir():
        print(
            f"bench: error: --json {args.json!r}: folder {str(Path(args.json).parent)!r} "
            f"does not exist",
            file=sys.stderr,
        )
        return 2
    return run(
        args.only,
        args.repeats,
        physics_steps=args.physics_steps,
        json_path=args.json,
        long_cycles=args.long_cycles,
    )


if __name__ == "__main__":
    sys.exit(main())
