"""Instructions a step, counted by valgrind's callgrind: the same count every run, where wall time
on a shared machine moves by a third from one minute to the next.

    python tools/step_instructions.py   # physics-only, the reads floor, twin alone, + MCAP, + both
    python tools/step_instructions.py --modes physics reads alone

Each mode runs pick_place at 2 and at 4 cycles under callgrind; a step's cost is the difference of
the twin process's totals over the difference of their steps, so the start (imports, the scene, the
recorders) cancels out. `physics` replays the same motion on the bare World as tools/bench.py's
same-motion baseline does (its actions are taken from a twin run outside valgrind); `reads` adds a
Frame's engine reads every step (bench_record's reads floor). Only the twin's
own process is counted: the recorder processes (forked, traced too) work on the other core. Needs
valgrind (`apt-get install valgrind`); takes about ten minutes.
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from bench import (  # tools/bench.py, beside this file: the same baseline
    motion_actions,
    replay_motion,
)

MODES = ("physics", "reads", "alone", "mcap", "both")
CYCLES = (2, 4)
ENV = {"OPENBLAS_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}  # no BLAS threads, no random hash order


def run_mode(mode: str, cycles: int, folder: Path) -> int:
    """One run, in this process (the one valgrind traces); returns its steps."""
    from twin.model.config import TwinConfig

    config = TwinConfig()
    if mode in ("physics", "reads"):
        from twin.sim.world import World

        n_steps, actions = pickle.loads((folder / f"actions{cycles}.pkl").read_bytes())
        world = World(config)
        # reads: the reads floor, a Frame's engine reads every step and nothing else
        replay_motion(
            world, n_steps, actions, (lambda _: world.state()) if mode == "reads" else None
        )
        world.close()
        return n_steps
    from twin.record import open_recorders
    from twin.sim.twin import Twin
    from twin.tasks import TASKS, run_task

    params = {"cycles": cycles}
    if mode == "alone":
        twin = Twin(config)
        run_task(twin, TASKS["pick_place"], params)
        twin.close()
        return twin.step_index
    run = {"source": "task", "task": "pick_place", "params": params}
    rrd = folder / f"{mode}{cycles}.rrd" if mode == "both" else None
    with open_recorders(
        config, run, mcap_path=folder / f"{mode}{cycles}.mcap", rrd_path=rrd
    ) as sinks:
        twin = Twin(config, sinks=sinks)
        run_task(twin, TASKS["pick_place"], params)
        twin.close()
    return twin.step_index


def callgrind_total(path: Path) -> int:
    """The instruction count a callgrind output file ends with."""
    for line in path.read_text().splitlines():
        if line.startswith(("summary:", "totals:")):
            return int(line.split()[1])
    raise ValueError(f"{path} holds no callgrind totals")


def counted(mode: str, cycles: int, folder: Path) -> tuple[int, int]:
    """(instructions of the twin's process, steps) of one run under callgrind."""
    out = folder / f"{mode}.{cycles}.%p"
    proc = subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            sys.executable,
            __file__,
            "--child",
            mode,
            str(cycles),
            str(folder),
        ],
        capture_output=True,
        text=True,
        env={**os.environ, **ENV},
        check=False,
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("steps ")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise SystemExit(f"step_instructions: the {mode} run under valgrind failed: {tail}")
    steps, pid = (int(v) for v in lines[-1].split()[1:3])
    return callgrind_total(folder / f"{mode}.{cycles}.{pid}"), steps


def per_step(runs: dict[int, tuple[int, int]]) -> float:
    """Instructions a step from two runs' (total, steps): the start cancels out."""
    (i_a, s_a), (i_b, s_b) = runs[CYCLES[0]], runs[CYCLES[1]]
    return (i_b - i_a) / (s_b - s_a)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument(
        "--child", nargs=3, metavar=("MODE", "CYCLES", "FOLDER"), help=argparse.SUPPRESS
    )
    args = parser.parse_args(argv)
    if args.child:
        mode, cycles, folder = args.child
        print(f"steps {run_mode(mode, int(cycles), Path(folder))} {os.getpid()}")
        return 0
    if shutil.which("valgrind") is None:
        print(
            "step_instructions: valgrind is not installed; expected it on PATH (apt-get "
            "install valgrind)",
            file=sys.stderr,
        )
        return 2
    results: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="twin_instructions_") as tmp:
        folder = Path(tmp)
        if "physics" in args.modes or "reads" in args.modes:
            for cycles in CYCLES:
                (folder / f"actions{cycles}.pkl").write_bytes(pickle.dumps(motion_actions(cycles)))
        for mode in args.modes:
            results[mode] = per_step({cycles: counted(mode, cycles, folder) for cycles in CYCLES})
            ratio = (
                f"  ({results['physics'] / results[mode]:.3f}x physics)"
                if "physics" in results
                else ""
            )
            print(f"{mode:8s} {results[mode] / 1000:8.1f}k instructions a step{ratio}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
