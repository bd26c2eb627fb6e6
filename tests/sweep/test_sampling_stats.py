"""Distributions, keys, per-scenario sampling and statistics: fast checks without running a task."""

from __future__ import annotations

import math

import pytest

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError
from twin.sweep.keys import apply_values, resolve_key
from twin.sweep.sampling import RandomSampler
from twin.sweep.spec import SweepSpec, dump_spec, load_spec, prepare
from twin.sweep.stats import reason, summarize, wilson
from twin.tasks import resolve


def _values(seed: int, vary: tuple, i: int) -> dict:
    prep = prepare(SweepSpec("pick_place", 10, seed=seed, vary=vary))
    return {k.name: v for k, v in RandomSampler(seed, prep.keys).values(i).items()}


def test_a_scenarios_values_depend_only_on_seed_index_and_key():
    x = ("box.x_m", "uniform(0.18, 0.22)")
    m = ("box.mass_kg", "choice(0.1, 0.5)")
    one = _values(7, (x,), 3)
    assert one == _values(7, (x,), 3)  # again, elsewhere: the same
    assert _values(7, (m, x), 3)["box.x_m"] == one["box.x_m"]  # another varied key changes nothing
    assert _values(8, (x,), 3) != one and _values(7, (x,), 4) != one
    draws = [_values(7, (x, m), i) for i in range(200)]
    assert all(0.18 <= d["box.x_m"] <= 0.22 for d in draws)
    assert {d["box.mass_kg"] for d in draws} == {0.1, 0.5}


def test_values_reach_the_configuration_and_are_checked_against_its_schema():
    config, fn = TwinConfig(), resolve("pick_place")
    keys = {name: resolve_key(name, config, fn, "pick_place") for name in
            ("box.x_m", "box.yaw_rad", "pad.max_pull_force_n", "robot.revolute_max_velocity_rad_s")}
    out = apply_values(
        config,
        {
            keys["box.x_m"]: 0.21,
            keys["box.yaw_rad"]: 0.1,
            keys["pad.max_pull_force_n"]: 5.0,
            keys["robot.revolute_max_velocity_rad_s"]: 2.0,
        },
    )
    assert out.objects[0].pos_m == (0.21, 0.7, 0.025) and out.objects[0].yaw_rad == 0.1
    assert out.suction.max_pull_force_n == 5.0 and out.profile.revolute_max_velocity_rad_s == 2.0
    with pytest.raises(
        ConfigError, match=r"^scenario: box.x_m = 'far' is invalid \(twin.config field objects"
    ):
        apply_values(config, {keys["box.x_m"]: "far"})


@pytest.mark.parametrize(
    ("vary", "message"),
    [
        (
            ("bax.x_m", "0.2"),
            (
                "--vary key 'bax.x_m' is unknown; expected "
                "<object>.x_m|y_m|z_m|yaw_rad|mass_kg|friction"
            ),
        ),
        (
            ("box.colour", "1"),
            "--vary key 'box.colour' is unknown; expected box. followed by one of x_m, y_m",
        ),
        (
            ("pad.strength", "1"),
            "--vary key 'pad.strength' is unknown; expected pad. followed by one of",
        ),
        (
            ("task.speed", "1"),
            "--vary key 'task.speed': task 'pick_place' takes no parameter 'speed'",
        ),
        (
            ("box.x_m", "uniform(0.3)"),
            "--vary box.x_m=uniform(0.3) is invalid; expected uniform(two finite numbers)",
        ),
        (("box.x_m", "uniform(2, 1)"), "expected uniform(a,b) with a < b"),
        (("box.x_m", "normal(0.2, 0)"), "expected normal(mu,sigma) with sigma > 0"),
        (
            ("box.x_m", "gauss(0.2, 1)"),
            "unknown distribution 'gauss'; expected uniform, normal or choice",
        ),
        (("box.mass_kg", "uniform(-1, 1)"), "box.mass_kg = -1.0 is invalid"),
        (("pad.infinite_strength", "uniform(0, 1)"), "expected true or false"),
        (("task.cycles", "uniform(1, 3)"), "the task's cycles takes int values (its default is 2)"),
    ],
)
def test_bad_keys_and_distributions_are_refused_before_anything_runs(vary, message):
    with pytest.raises(ConfigError) as err:
        prepare(SweepSpec("pick_place", 10, vary=(vary,)))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_wilson_interval_matches_the_formula_and_stays_in_0_1():
    lo, hi = wilson(90, 100)
    # textbook values
    assert math.isclose(lo, 0.8256, abs_tol=1e-4) and math.isclose(hi, 0.9448, abs_tol=1e-4)
    assert wilson(0, 10)[0] == 0.0 and wilson(10, 10)[1] == 1.0 and wilson(0, 0) == (0.0, 1.0)
    assert 0 < wilson(0, 10)[1] < 0.35 and 0.65 < wilson(10, 10)[0] < 1


def test_summary_groups_failures_by_reason_and_skips_runs_that_never_placed():
    rows = [{"outcome": "ok", "error": "", "placement_error_mm": e} for e in (1.0, 2.0, 3.0)] + [
        {
            "outcome": "error",
            "error": "cycle 2: placed 3.10 mm from (0.2, 0.7), beyond 2 mm",
            "placement_error_mm": 3.1,
        },
        {
            "outcome": "error",
            "error": "cycle 1: suction on at (0.2, 0.7), nothing sensed",
            "placement_error_mm": None,
        },
        {
            "outcome": "error",
            "error": "cycle 1: suction on at (0.2, 0.7), nothing sensed",
            "placement_error_mm": None,
        },
    ]
    s = summarize(rows)
    assert (s["scenarios"], s["ok"], s["failed"], s["success_rate"]) == (6, 3, 3, 0.5)
    assert s["placement_error_mm"] == pytest.approx(
        {"count": 4, "p50": 2.5, "p95": 3.085, "max": 3.1}
    )
    assert s["failures_by_reason"] == {
        "suction on at (#, #), nothing sensed": 2,
        "placed # mm from (#, #), beyond # mm": 1,
    }
    assert reason("") == "error"


def test_a_definition_round_trips_through_toml(tmp_path):
    spec = SweepSpec(
        "pick_place",
        25,
        robot="seed001",
        seed=3,
        vary=(("box.x_m", "normal(0.2, 0.01)"),),
        params={"cycles": 1, "keep_going": True, "box": "box"},
        timeout_s=30.0,
        tolerance={"placement_p95_mm": 2.0},
    )
    (tmp_path / "s.toml").write_text(dump_spec(spec))
    assert load_spec(tmp_path / "s.toml") == spec
    (tmp_path / "bad.toml").write_text('task = "pick_place"\nscenarios = 10\nspeed = 2\n')
    with pytest.raises(ConfigError, match="has unknown field 'speed'"):
        load_spec(tmp_path / "bad.toml")


def test_a_draw_outside_the_schema_fails_its_scenario_not_the_sweep():
    from twin.sweep.worker import Job, run_scenario

    spec = SweepSpec(
        "pick_place", 20, seed=1, vary=(("box.mass_kg", "normal(0.05, 0.1)"),), params={"cycles": 1}
    )
    sampler = RandomSampler(1, prepare(spec).keys)
    i = next(i for i in range(20) if next(iter(sampler.values(i).values())) <= 0)
    row = run_scenario(Job(spec, None, "none"), i)
    assert row["outcome"] == "error" and row["error"].startswith(f"scenario {i}: box.mass_kg = -")
    assert row["placement_error_mm"] is None and row["attach"] == 0 and row["sim_s"] == 0.0
