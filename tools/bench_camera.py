"""Benchmark section: what a camera costs.

The cost of one picture (PyBullet's tiny renderer in the twin's render world, then PNG), for the
overhead and the wrist camera at 320x240; and a recorded pick_place run (MCAP) with the overhead
camera at 15 Hz of simulated time, in steps per wall second and as a ratio to the physics-only
baselines (`record_camera_vs_motion`: pictures drawn in the render process, as twin does;
`record_camera_in_thread_vs_motion`: drawn in the stepping thread). A picture is rendered every 16
steps at 240 Hz, so a camera run is bound by its pictures: the "render bound" row is the step rate
of a renderer doing nothing else, from the picture cost alone. `python tools/bench_camera.py` runs
it alone (with the baseline).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

from twin.model.config import TwinConfig
from twin.model.images import camera, camera_view
from twin.pictures import encode
from twin.record import open_recorders
from twin.sim.camera import RenderWorld
from twin.sim.twin import Twin
from twin.tasks import TASKS, run_task

CYCLES = 2
PICTURES = 30  # per timing sample
RUN = {"source": "task", "task": "pick_place", "params": {"cycles": CYCLES}}


def picture_ms(name: str) -> tuple[float, float]:
    """(render ms, PNG ms) of one picture from this built-in camera, the arm mid-move."""
    spec = camera(name)
    config = TwinConfig(cameras=(spec,))
    twin = Twin(TwinConfig())
    frame = twin.step(300)
    twin.close()
    world = RenderWorld(config)
    try:
        world.pose(frame)
        view = camera_view(spec, frame.pad_pose)
        t0 = time.perf_counter()
        for _ in range(PICTURES):
            pixels = world.render(spec, *view)
        t1 = time.perf_counter()
        for _ in range(PICTURES):
            encode(pixels, spec.format)
        t2 = time.perf_counter()
    finally:
        world.close()
    return (t1 - t0) * 1e3 / PICTURES, (t2 - t1) * 1e3 / PICTURES


def recorded_camera_run(folder: Path, *, background: bool = True) -> tuple[float, int]:
    """(steps/s, pictures) of pick_place recorded to MCAP with the overhead camera, twin built to
    files finalized excluded: stepping only, as the physics baselines are timed. background False:
    the pictures drawn in the stepping thread (Twin(camera_background=False))."""
    config = TwinConfig(cameras=(camera("overhead"),))
    with open_recorders(config, RUN, mcap_path=folder / "camera.mcap") as sinks:
        twin = Twin(config, sinks=sinks, camera_background=background)
        t0 = time.perf_counter()
        run_task(twin, TASKS["pick_place"], {"cycles": CYCLES})
        rate = twin.step_index / (time.perf_counter() - t0)
        twin.close()
    pictures = twin.step_index // config.cameras[0].every_steps(config.dt_ns) + 1
    return rate, pictures


def bench(ctx) -> list[tuple[str, str]]:
    repeats = max(3, int(ctx.repeats))
    rows = []
    every = camera("overhead").every_steps(TwinConfig().dt_ns)
    costs = {}
    for name in ("overhead", "wrist"):
        samples = [picture_ms(name) for _ in range(repeats)]
        render, png = (statistics.median(s[i] for s in samples) for i in range(2))
        costs[name] = render + png
        ctx.figures[f"camera_{name}_ms_per_picture"] = render + png
        rows.append(
            (
                f"one {name} picture, 320x240: render + PNG (median of {repeats})",
                f"{render + png:.2f} ms ({render:.2f} + {png:.2f})",
            )
        )
    with tempfile.TemporaryDirectory(prefix="twin-bench-camera-") as tmp:
        runs, here = [], []
        for _ in range(repeats):  # the two ways take turns: a machine that slows down slows both
            runs.append(recorded_camera_run(Path(tmp)))
            here.append(recorded_camera_run(Path(tmp), background=False)[0])
    rate = statistics.median(r[0] for r in runs)
    ctx.rate_figures("record_camera", rate)
    label = (
        f"twin + MCAP + overhead camera at 15 Hz (a picture every {every} steps, "
        f"{runs[0][1]} pictures), "
        "rendered in the render process: steps/s"
    )
    rows.append((label, ctx.ratio(rate)))
    in_thread = statistics.median(here)
    ctx.rate_figures("record_camera_in_thread", in_thread)
    rows.append(("the same, rendered in the stepping thread: steps/s", ctx.ratio(in_thread)))
    bound = every * 1e3 / costs["overhead"]
    ctx.figures["camera_render_bound_steps_per_s"] = bound
    rows.append(
        ("render bound: steps/s of a renderer drawing nothing but the pictures", f"{bound:,.0f}")
    )
    return rows


if __name__ == "__main__":
    from bench import main  # tools/ is sys.path[0] when run as a script

    sys.exit(main(["--only", "camera", *sys.argv[1:]]))
