"""Every golden in recordings/ re-runs and replays to a match under the default verdict (bits here,
or within the measured noise floor on another machine); the `golden` pytest fixture works."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from twin.compare.tolerances import DEFAULT, Tolerances
from twin.model.profiles import PROFILES
from twin.record.mcap.reader import load
from twin.verify.check import check_all

ROOT = Path(__file__).resolve().parents[2]
RECORDINGS = ROOT / "recordings"
GOLDENS = sorted(p for p in RECORDINGS.glob("*.mcap") if not p.name.endswith(".obtained.mcap"))

pytest_plugins = ["pytester"]


def _regen_module():
    spec = importlib.util.spec_from_file_location(
        "regen_goldens", ROOT / "tools" / "regen_goldens.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_every_golden_rerun_matches():
    assert GOLDENS, "recordings/ holds no goldens"
    outcomes = check_all([str(p) for p in GOLDENS], Tolerances.from_preset(DEFAULT), jobs=2)
    bad = {Path(o.path).name: o.summary for o in outcomes if o.status != "match"}
    assert not bad, "\n".join(f"{name}: {why}" for name, why in bad.items()) + (
        "\n(if the change is intended: python tools/regen_goldens.py rewrites every "
        "golden with this machine's "
        "runs; review `twin diff` old vs new first)"
    )


@pytest.mark.parametrize("path", GOLDENS, ids=lambda p: p.stem)
def test_every_golden_replays_to_a_match_with_every_event(path, tmp_path):
    """Replay feeds the file's commands (what the task said included) back: nothing may differ
    beyond noise."""
    from twin.verify.noise import judge
    from twin.verify.replay import replay, replayed_event_kinds

    golden = load(path)
    assert replayed_event_kinds(golden) is None  # annotations are Commands: every event compares
    result = judge(golden, replay(golden), Tolerances.from_preset(DEFAULT), replay, source=golden)
    assert result.match, result.first
    assert result.events_matched == len(golden.events)


def test_the_goldens_are_the_documented_set():
    regen = _regen_module()
    made = {g.name for g in [*regen.goldens(), *regen.sessions()]}
    assert {p.stem for p in GOLDENS} == made
    readme = (RECORDINGS / "README.md").read_text()
    assert all(f"{name}.mcap" in readme for name in made)
    profiles = {load(p).config.profile.name for p in GOLDENS}
    assert profiles == set(PROFILES)
    assert sum(p.stat().st_size for p in GOLDENS) < 5e6


def test_remaking_a_session_golden_replaces_the_file(tmp_path):
    """tools/regen_goldens.py remakes a session golden over the one in place (the server is asked
    to replace it: a plain `twin serve --record` refuses an existing file)."""
    regen = _regen_module()
    session = next(s for s in regen.sessions() if s.name == "session_seed002")  # the shortest
    (tmp_path / "session_seed002.mcap").write_bytes(b"an older golden")
    path = regen.make_session(session, tmp_path)
    assert load(path).run["source"] == "remote"


def test_a_golden_holds_a_suction_break():
    rec = load(RECORDINGS / "pick_place_break_mtb.mcap")
    assert not rec.config.suction.infinite_strength
    assert any(e.kind == "break" for e in rec.events)
    assert rec.run == {"source": "task", "task": "pick_place", "params": {"cycles": 1}}


# the inner runs are in this process (pytester.runpytest): a new interpreter each cost 7 s of 34;
# pytest-benchmark would warn there that xdist (the outer run's) is active
INNER = ("-p", "no:cacheprovider", "-p", "no:benchmark")

PLUGIN_TEST = """
import os
from twin.verify.check import record_task
from twin.model.config import TwinConfig

def test_run(golden):
    run = record_task(TwinConfig(), "pick_place", {"cycles": 1})
    if os.environ.get("TWIN_TAMPER"):
        run.frames.object_poses[400:, 0, 1] += 0.003
    tolerance = {"tolerance": os.environ["TWIN_TOL"]} if "TWIN_TOL" in os.environ else {}
    golden.check(run, "one_cycle", **tolerance)
"""


def test_golden_fixture_writes_checks_reports_and_updates(pytester, monkeypatch):
    pytester.makeini("[pytest]\ntwin_goldens_dir = goldens\n")
    pytester.makepyfile(test_plugin=PLUGIN_TEST)
    goldens = pytester.path / "goldens"

    first = pytester.runpytest(*INNER)
    first.assert_outcomes(failed=1)
    assert "did not exist; wrote it" in first.stdout.str() and (goldens / "one_cycle.mcap").exists()
    pytester.runpytest(*INNER).assert_outcomes(passed=1)

    monkeypatch.setenv("TWIN_TAMPER", "1")
    failed = pytester.runpytest(*INNER)
    failed.assert_outcomes(failed=1)
    assert "step 400" in failed.stdout.str()
    assert (goldens / "one_cycle.obtained.mcap").exists() and (
        goldens / "one_cycle.report.md"
    ).exists()
    monkeypatch.setenv("TWIN_TOL", "outcome")
    # lands within 5 mm
    pytester.runpytest(*INNER).assert_outcomes(passed=1)
    monkeypatch.delenv("TWIN_TOL")

    pytester.runpytest(*INNER, "--update-goldens").assert_outcomes(
        passed=1
    )
    assert not (goldens / "one_cycle.obtained.mcap").exists()
    pytester.runpytest(*INNER).assert_outcomes(passed=1)


FAILING_TEST = """
import os
from twin.verify.check import record_task
from twin.model.config import TwinConfig

def test_run(golden):
    params = {"cycles": 1, "max_error_m": 1e-9} if os.environ.get("TWIN_FAIL") else {"cycles": 1}
    golden.check(record_task(TwinConfig(), "pick_place", params), "one_cycle",
                 allow_error=bool(os.environ.get("TWIN_ALLOW")))
"""


def test_golden_fixture_never_makes_a_golden_of_a_failed_run(pytester, monkeypatch):
    pytester.makeini("[pytest]\ntwin_goldens_dir = goldens\n")
    pytester.makepyfile(test_plugin=FAILING_TEST)
    golden = pytester.path / "goldens" / "one_cycle.mcap"
    monkeypatch.setenv("TWIN_FAIL", "1")
    first = pytester.runpytest(*INNER)
    first.assert_outcomes(failed=1)
    assert (
        "this run cannot become it: its task ended error" in first.stdout.str()
        and not golden.exists()
    )
    # still not written
    pytester.runpytest(*INNER).assert_outcomes(failed=1)
    monkeypatch.delenv("TWIN_FAIL")
    # written from the ok run
    pytester.runpytest(*INNER).assert_outcomes(failed=1)
    assert golden.exists()
    monkeypatch.setenv("TWIN_FAIL", "1")
    update = pytester.runpytest(*INNER, "--update-goldens")
    update.assert_outcomes(failed=1)
    assert "rerun with --update-goldens" not in update.stdout.str()
    assert "this run cannot become the golden: its task ended error" in update.stdout.str()
    monkeypatch.setenv("TWIN_ALLOW", "1")
    pytester.runpytest(*INNER, "--update-goldens").assert_outcomes(
        passed=1
    )
