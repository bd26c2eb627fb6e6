"""`twin diff` and `twin check` on real MCAP recordings: exit codes, reports, sensitivity, bad
input."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from support.cli import twin
from support.runs import record_pick_place

from twin.compare.tolerances import Tolerances
from twin.model.config import EngineParams, SceneObject, TwinConfig
from twin.model.profiles import PROFILES
from twin.record.mcap.reader import load
from twin.verify.check import check_all
from twin.verify.replay import save

BASE = TwinConfig()
PARAMS = {"cycles": 1}
VARIANTS = {
    "link": dataclasses.replace(
        BASE, profile=dataclasses.replace(BASE.profile, link1_m=BASE.profile.link1_m + 0.001)
    ),
    "box": dataclasses.replace(BASE, objects=(SceneObject("box", pos_m=(0.201, 0.7, 0.025)),)),
    "solver": dataclasses.replace(BASE, engine=EngineParams(num_solver_iterations=40)),
    "seed003": dataclasses.replace(BASE, profile=PROFILES["seed003"]),
}


def record_file(path, config: TwinConfig, params: dict = PARAMS):
    """Record a pick_place run to path through the real recorder; returns the in-memory run too."""
    return record_pick_place(path, config, params)


def first_change(a, b) -> int:
    """The first step where two in-memory frame streams differ, computed without twin.compare."""
    n = min(len(a), len(b))
    steps = [
        int(np.flatnonzero((getattr(a, c)[:n] != getattr(b, c)[:n]).reshape(n, -1).any(axis=1))[0])
        for c in (
            "joint_q",
            "joint_qd",
            "joint_effort",
            "hold_force_n",
            "hold_torque_nm",
            "pad_pose",
            "object_poses",
            "held_body",
            "sensed_body",
        )
        if (getattr(a, c)[:n] != getattr(b, c)[:n]).any()
    ]
    return min(steps + ([n] if len(a) != len(b) else []))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("recs")
    runs = {
        "golden": record_file(d / "golden.mcap", BASE),
        "again": record_file(d / "again.mcap", BASE),
    }
    for name, config in VARIANTS.items():
        runs[name] = record_file(d / f"{name}.mcap", config)
    return d, runs


def test_rerunning_the_same_task_matches_exactly(files, capsys):
    d, _ = files
    code, out, err = twin(capsys, "diff", d / "golden.mcap", d / "again.mcap")
    assert (code, err) == (0, "")
    # the default, on one machine
    assert out.startswith("MATCH (tolerance noise") and "  bit-identical\n" in out
    assert (d / "golden.mcap").read_bytes() == (d / "again.mcap").read_bytes()


@pytest.mark.parametrize("change", ["link", "box", "solver"])
def test_diff_exits_1_at_or_before_the_first_change(files, capsys, change):
    d, runs = files
    code, out, err = twin(capsys, "diff", d / "golden.mcap", d / f"{change}.mcap")
    assert code == 1 and err == ""
    step = int(
        re.search(r"^first divergence: step (\d+) \(t = ([0-9.]+) s\)", out, re.MULTILINE).group(1)
    )
    assert step <= first_change(runs["golden"].frames, runs[change].frames)
    assert "expected" in out and "difference" in out and "tolerance" in out


def test_outcome_passes_the_solver_change_but_not_the_link_change_at_exact(files, capsys):
    d, runs = files
    g, s = (
        runs["golden"].frames.object_poses[-1, 0, :3],
        runs["solver"].frames.object_poses[-1, 0, :3],
    )
    assert np.linalg.norm(g - s) < 5e-3
    assert (
        twin(capsys, "diff", d / "golden.mcap", d / "solver.mcap", "--tolerance", "outcome")[0] == 0
    )
    assert (
        twin(capsys, "diff", d / "golden.mcap", d / "solver.mcap", "--tolerance", "tight")[0] == 1
    )


def test_reports_for_ci(files, capsys, tmp_path):
    d, _ = files
    md, js, xml = tmp_path / "r.md", tmp_path / "r.json", tmp_path / "r.xml"
    code, _out, _ = twin(
        capsys,
        "diff",
        d / "golden.mcap",
        d / "box.mcap",
        "--report",
        md,
        "--report",
        js,
        "--report",
        xml,
        "--tol",
        "objects.position=0.002",
        "--tol",
        "final=0.002",
    )
    assert code == 1
    data = json.loads(js.read_text())
    assert data["match"] is False and data["first"]["step"] >= 0
    assert data["tolerances"]["fields"]["objects.position"] == 0.002
    assert "## First divergence" in md.read_text()
    suite = ET.parse(xml).getroot().find("testsuite")
    assert int(suite.get("failures")) >= 1 and int(suite.get("tests")) > 10


def test_another_profile_is_a_mismatch_naming_the_profile(files, capsys):
    d, _ = files
    code, out, err = twin(capsys, "diff", d / "golden.mcap", d / "seed003.mcap")
    assert code == 1 and err == "" and out.startswith("MISMATCH")
    assert "profile.name 'mtb' -> 'seed003'" in out


@pytest.mark.parametrize(
    ("make", "args", "expected"),
    [
        ("missing", [], "does not exist"),
        ("truncated", [], "truncated"),
        ("text", [], "not an MCAP file"),
        ("golden", ["--tol", "joints.position"], "malformed"),
        ("golden", ["--tol", "joints.angle=1e-3"], "unknown field 'joints.angle'"),
        ("golden", ["--tol", "pad.position=-1"], "expected a number >= 0 or inf"),
        ("golden", ["--tolerance", "loose"], "unknown tolerance preset 'loose'"),
        ("golden", ["--event-window", "-3"], "--event-window: '-3' is not a whole number >= 0"),
        ("golden", ["--report", "out.pdf"], "unknown extension '.pdf'"),
    ],
)
def test_bad_input_gives_one_line_and_exit_2(files, capsys, tmp_path, make, args, expected):
    d, _ = files
    candidate = d / "golden.mcap"
    if make == "missing":
        candidate = tmp_path / "nope.mcap"
    elif make == "truncated":
        data = (d / "golden.mcap").read_bytes()
        candidate = tmp_path / "cut.mcap"
        candidate.write_bytes(data[: len(data) // 2])
    elif make == "text":
        candidate = tmp_path / "notes.mcap"
        candidate.write_text("not a recording\n")
    code, out, err = twin(capsys, "diff", d / "golden.mcap", candidate, *args)
    assert code == 2 and out == ""
    assert err.startswith("twin: error: ") and err.count("\n") == 1 and expected in err


def test_rrd_diff_view_shows_both_runs_and_the_error(files, capsys, tmp_path):
    from twin.record.rerun.rrd_file import read_scalars

    d, runs = files
    rrd = tmp_path / "diff.rrd"
    assert twin(capsys, "diff", d / "golden.mcap", d / "box.mcap", "--rrd", rrd, "-q")[0] == 1
    assert rrd.read_bytes()[:4] == b"RRF2"
    steps, err_m = read_scalars(rrd, "/error/pose/objects.position")
    assert len(steps) == len(runs["golden"].frames)
    assert err_m[0] == pytest.approx(0.001)  # the box starts 1 mm away


def tamper(src, dst, step: int, dx_m: float) -> None:
    """A golden whose box drifts dx_m from `step` on: what a behaviour change looks like to
    check."""
    rec = load(src)
    rec.frames.object_poses[step:, 0, 0] += dx_m
    save(rec, dst)


def test_check_finds_a_changed_golden_and_update_rewrites_it(files, capsys, tmp_path):
    d, _ = files
    shutil.copy(d / "golden.mcap", tmp_path / "a.mcap")
    tamper(d / "golden.mcap", tmp_path / "b.mcap", 300, 0.002)
    code, out, err = twin(
        capsys, "check", tmp_path, "--jobs", "2", "--junit", tmp_path / "check.xml"
    )
    assert code == 1
    suite = ET.parse(tmp_path / "check.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures")) == ("2", "1")
    assert suite.find("testcase[@name='b.mcap']/failure").get("message").startswith("step 300")
    assert re.search(r"b\.mcap\s+differ .*step 300", out) and re.search(r"a\.mcap\s+match", out)
    assert "[2/2]" in err  # plain progress lines when not on a terminal
    code, out, _ = twin(capsys, "check", tmp_path, "--update")
    assert code == 0 and "rewrote: " in out and "b.mcap" in out.split("rewrote: ")[1]
    assert twin(capsys, "check", tmp_path / "a.mcap", tmp_path / "b.mcap")[0] == 0


def test_check_tolerance_applies(files, tmp_path):
    d, _ = files
    tamper(d / "golden.mcap", tmp_path / "b.mcap", 300, 0.002)
    outcomes = check_all(
        [str(tmp_path / "b.mcap")],
        Tolerances.from_preset("outcome").with_overrides(["final=0.005"]),
    )
    assert [o.status for o in outcomes] == ["match"]


def test_check_bad_input(capsys, tmp_path):
    code, _, err = twin(capsys, "check", tmp_path / "none.mcap")
    assert code == 2 and "does not exist" in err
    code, _, err = twin(capsys, "check", tmp_path)
    assert code == 2 and "holds no goldens; expected .mcap recordings" in err
    code, _, err = twin(capsys, "check", tmp_path, "--jobs", "0")
    assert code == 2 and "--jobs/-j: '0' is not a whole number >= 1" in err
