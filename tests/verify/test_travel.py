"""Verdicts that travel: goldens check on simulated other machines, and real changes are still
caught there.

Other machines are simulated on this one: OPENBLAS_CORETYPE picks numpy's BLAS/LAPACK kernel (as
another CPU does), NPY_DISABLE_CPU_FEATURES switches numpy's SIMD dispatch, and GLIBC_TUNABLES takes
glibc's libm off its FMA code paths (as on a CPU without FMA). Each runs `twin` in a child process
with that setting.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.cli import twin_child as twin_cli
from twin.record.mcap.reader import load

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = sorted(
    p for p in (ROOT / "recordings").glob("*.mcap") if not p.name.endswith(".obtained.mcap")
)
BLAS_CORES = ("Prescott", "Haswell", "SkylakeX", "Zen")
NO_FMA = {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"}
MACHINES = {"here": {}, "no-fma libm": NO_FMA, "SkylakeX BLAS": {"OPENBLAS_CORETYPE": "SkylakeX"}}


@pytest.fixture(scope="module")
def local_goldens(tmp_path_factory) -> Path:
    """The committed goldens remade on this machine (twin check --update --tolerance exact on
    copies)."""
    d = tmp_path_factory.mktemp("local_goldens")
    for p in GOLDENS:
        shutil.copy(p, d / p.name)
    done = twin_cli("check", "--update", "--allow-error", "--tolerance", "exact", "-j", "2", d)
    assert done.returncode == 0, done.stdout + done.stderr
    return d


@pytest.mark.slow
@pytest.mark.parametrize("core", BLAS_CORES)
def test_goldens_made_here_are_bit_identical_under_every_blas_kernel(local_goldens, core):
    done = twin_cli(
        "check", "--tolerance", "exact", "-j", "2", local_goldens, env={"OPENBLAS_CORETYPE": core}
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"{len(GOLDENS)} match" in done.stdout


@pytest.mark.slow
def test_goldens_made_here_are_bit_identical_without_numpys_simd_dispatch(local_goldens):
    import numpy as np

    found = [
        name
        for name, on in np._core._multiarray_umath.__cpu_features__.items()
        if on and name.startswith("AVX")
    ]
    done = twin_cli(
        "check",
        "--tolerance",
        "exact",
        "-j",
        "2",
        local_goldens,
        env={"NPY_DISABLE_CPU_FEATURES": " ".join(found)},
    )
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("machine", ["no-fma libm", "SkylakeX BLAS"])
def test_the_committed_goldens_pass_the_default_check_on_other_machines(machine):
    done = twin_cli("check", "-j", "2", cwd=ROOT, env=MACHINES[machine])
    assert done.returncode == 0, done.stdout + done.stderr
    # every golden under recordings/: the .mcap files, the sweep and the search golden
    assert done.stdout.startswith(f"checking {len(GOLDENS) + 2} goldens: {len(GOLDENS)} recordings")
    assert f"\n{len(GOLDENS) + 2} match\n" in done.stdout


# -- sensitivity: a user's task file, recorded on one machine, changed, checked on another ---------

TASK = """
def run(twin, target_x_m=0.2, late_steps=0, pause_s=0.5):
    twin.raise_()
    twin.move_to(0.2, 0.7)
    twin.lower()
    twin.step(late_steps)
    twin.suction(True)
    twin.wait(pause_s)
    twin.raise_()
    twin.move_to(target_x_m, -0.55)
    twin.lower()
    twin.suction(False)
    twin.wait(0.3)
    twin.raise_()
"""
CHANGES = {
    "1 mm target": "target_x_m=0.201",
    "1 step late suction": "late_steps=1",
    "5 ms longer wait": "pause_s=0.505",
}


@pytest.fixture(scope="module")
def user_golden(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("user_task")
    (d / "my_task.py").write_text(TASK)
    done = twin_cli("run", d / "my_task.py", "--record", d / "golden.mcap")
    assert done.returncode == 0, done.stdout + done.stderr
    return d


@pytest.mark.slow
@pytest.mark.parametrize("machine", list(MACHINES))
def test_an_unchanged_user_task_checks_green_everywhere(user_golden, machine):
    done = twin_cli("check", user_golden / "golden.mcap", env=MACHINES[machine])
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.fixture(scope="module")
def onsets() -> dict[str, int]:
    """change -> the first step where the changed task's run here differs from the golden: the
    same run for every machine, so recorded once a change (the first test of it fills it in)."""
    return {}


@pytest.mark.slow
@pytest.mark.parametrize("machine", list(MACHINES))
@pytest.mark.parametrize("change", list(CHANGES))
def test_a_changed_user_task_fails_the_default_check_at_its_onset(
    user_golden, onsets, tmp_path, machine, change
):
    d = tmp_path / "work"
    shutil.copytree(user_golden, d)
    name, value = CHANGES[change].split("=")
    source = (d / "my_task.py").read_text()
    (d / "my_task.py").write_text(re.sub(rf"{name}=[0-9.]+", f"{name}={value}", source, count=1))
    if change not in onsets:  # here, for the onset
        changed = twin_cli("run", d / "my_task.py", "--record", d / "changed.mcap")
        assert changed.returncode == 0, changed.stderr
        onsets[change] = _first_change(load(d / "golden.mcap"), load(d / "changed.mcap"))
    onset = onsets[change]
    done = twin_cli("check", "-v", d / "golden.mcap", env=MACHINES[machine])
    assert done.returncode == 1, done.stdout + done.stderr
    step = int(re.search(r"^first divergence: step (\d+)", done.stdout, re.MULTILINE).group(1))
    assert step <= onset, done.stdout


def _first_change(a, b, above: float = 0.0) -> int:
    """The first step where two runs' frames differ by more than `above` (any bit, for 0) or the
    commands that act differ, computed without twin.compare."""
    import numpy as np

    n = min(len(a.frames), len(b.frames))
    steps = [n]
    for column in (
        "joint_q",
        "joint_qd",
        "joint_effort",
        "joint_target",
        "pad_pose",
        "object_poses",
        "suction_on",
    ):
        x, y = getattr(a.frames, column)[:n], getattr(b.frames, column)[:n]
        moved = (x != y) if above == 0 else np.abs(x.astype(float) - y.astype(float)) > above
        rows = np.flatnonzero(moved.reshape(n, -1).any(axis=1))
        if len(rows):
            steps.append(int(a.frames.step[rows[0]]))
    # annotations apart
    acting_a, acting_b = ([c for c in r.commands if c.kind != "event"] for r in (a, b))
    diff = [x.step for x, y in zip(acting_a, acting_b, strict=False) if x != y]
    return min(steps + diff[:1])


# -- sensitivity: a configuration change, run on another machine, diffed against a golden here ---

CONFIG_CHANGES = {
    "1 mm link": "replace(BASE, profile=replace(BASE.profile, link1_m=BASE.profile.link1_m + "
    "0.001))",
    "1 mm box": "replace(BASE, objects=(replace(BASE.objects[0], pos_m=(0.201, 0.7, 0.025)),))",
    "1 % mass": "replace(BASE, objects=(replace(BASE.objects[0], mass_kg=BASE.objects[0].mass_kg "
    "* 1.01),))",
    "solver": "replace(BASE, engine=replace(BASE.engine, num_solver_iterations=40))",
    "none": "BASE",
}
RECORD = """
import sys
from dataclasses import replace
from twin.model.config import TwinConfig
from twin.verify.check import record_task
from twin.verify.replay import save
BASE = TwinConfig()
save(record_task({config}, "pick_place", {{"cycles": 1}}), sys.argv[1])
"""


def _record(config: str, path: Path, env: dict[str, str]) -> None:
    done = subprocess.run(
        [sys.executable, "-c", RECORD.format(config=config), str(path)],
        check=False,
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        timeout=600,
    )
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="module")
def config_golden(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("config_golden")
    _record("BASE", d / "golden.mcap", {})
    return d / "golden.mcap"


@pytest.mark.slow
# BLAS kernels give the same bits (the exact checks above)
@pytest.mark.parametrize("machine", ["no-fma libm"])
@pytest.mark.parametrize("change", list(CONFIG_CHANGES))
def test_a_changed_configuration_run_elsewhere_fails_the_default_diff(
    config_golden, tmp_path, machine, change
):
    env = MACHINES[machine]
    _record(CONFIG_CHANGES[change], tmp_path / "elsewhere.mcap", env)
    done = twin_cli("diff", config_golden, tmp_path / "elsewhere.mcap", env=env)
    if change == "none":
        assert done.returncode == 0, done.stdout + done.stderr
        return
    assert done.returncode == 1, done.stdout + done.stderr
    _record(CONFIG_CHANGES[change], tmp_path / "here.mcap", {})
    # a change that starts below tight's 1e-9 (1 % mass moves the resting box by 1e-17 m) shows
    # where it passes it
    onset = _first_change(load(config_golden), load(tmp_path / "here.mcap"), above=1e-9)
    step = int(re.search(r"^first divergence: step (\d+)", done.stdout, re.MULTILINE).group(1))
    assert step <= onset, done.stdout
