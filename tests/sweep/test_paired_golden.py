"""Paired statistical goldens: `twin check --update NAME.toml` keeps NAME.results.parquet beside the
definition, and `twin check NAME.toml` pairs the new run with it scenario by scenario: flips both
ways are named even when the success rate stays the same, by the [tolerance] rule; the verdict is
the same whatever the executor or job count."""

from __future__ import annotations

import json
import os
import shutil

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from twin.cli.main import main
from twin.jobs.executors import make_executor
from twin.sweep import power
from twin.sweep.golden import check_sweep

DEFINITION = """\
task = "pick_place"
seed = 3
scenarios = 20

[params]
cycles = 1
pause_s = 0.1
max_error_m = 0.03

[vary]
"box.x_m" = "normal(0.2, 0.012)"
"box.y_m" = "normal(0.7, 0.012)"
"""


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    folder = tmp_path_factory.mktemp("paired")
    (folder / "small.toml").write_text(DEFINITION)
    assert main(["check", str(folder / "small.toml"), "--update", "--jobs", "2"]) == 0
    return folder


def test_update_keeps_the_per_scenario_results_and_check_pairs_them(golden, capsys):
    table = pq.read_table(golden / "small.results.parquet")
    assert table.column_names == [
        "scenario",
        "box.x_m",
        "box.y_m",
        "outcome",
        "error",
        "placement_error_mm",
    ]
    assert table.column("scenario").to_pylist() == list(range(20))
    meta = json.loads(table.schema.metadata[b"twin.sweep"])
    assert meta == {
        "seed": 3,
        "vary": [["box.x_m", "normal(0.2, 0.012)"], ["box.y_m", "normal(0.7, 0.012)"]],
    }
    summary = json.loads((golden / "small.summary.json").read_text())
    assert summary["ok"] == pc.sum(pc.equal(table.column("outcome"), "ok")).as_py()
    assert 0 < summary["ok"] < 20  # some boxes start out of the pad's reach: both outcomes occur
    capsys.readouterr()
    assert main(["check", str(golden / "small.toml"), "-v"]) == 0
    assert " match " in capsys.readouterr().out


def _swap_two(golden, folder, strict: bool):
    """A copy of the golden whose results have one ok and one failed scenario swapped, as if the
    code that made them flipped those two both ways: the same success rate."""
    text = DEFINITION + ('\n[tolerance]\npaired = "strict"\n' if strict else "")
    (folder / "g.toml").write_text(text)
    shutil.copy(golden / "small.summary.json", folder / "g.summary.json")
    table = pq.read_table(golden / "small.results.parquet")
    rows = table.to_pylist()
    ok = next(r for r in rows if r["outcome"] == "ok")
    failed = next(r for r in rows if r["outcome"] != "ok")
    ok_copy = dict(ok)
    ok.update(
        outcome=failed["outcome"],
        error=failed["error"],
        placement_error_mm=failed["placement_error_mm"],
    )
    failed.update(outcome="ok", error="", placement_error_mm=ok_copy["placement_error_mm"])
    pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), folder / "g.results.parquet")
    return folder / "g.toml", ok["scenario"], failed["scenario"]


def test_flips_both_ways_at_the_same_rate_are_named_and_fail_under_strict(golden, tmp_path, capsys):
    definition, became_ok, became_failed = _swap_two(golden, tmp_path, strict=True)
    capsys.readouterr()
    assert main(["check", str(definition)]) == 1
    out = capsys.readouterr().out
    assert " differ " in out
    assert (
        f"2 scenarios flipped (strict: any flip fails): ok->failed 1 ({became_failed}), "
        f"failed->ok 1 ({became_ok})"
    ) in out
    assert (
        f"re-run: twin sweep {definition} --only {became_failed} --out runs/s{became_failed}" in out
    )
    assert main(["check", str(definition), "-v"]) == 1
    report = capsys.readouterr().out
    assert (
        f"scenario {became_failed}: box.x_m=" in report
        and "paired difference +0.00 points" in report
    )
    assert "McNemar exact p = 1" in report
    assert (
        main(
            [
                "sweep",
                str(definition),
                "--only",
                str(became_failed),
                "--out",
                str(tmp_path / "again"),
                "--quiet",
            ]
        )
        == 0
    )  # the re-run the verdict names: that scenario, recorded
    assert (tmp_path / "again" / "failures" / f"scenario-{became_failed}.mcap").exists()


def test_keep_writes_a_paired_sweep_s_results_too(golden, tmp_path, capsys):
    definition, _, _ = _swap_two(golden, tmp_path, strict=True)
    keep = tmp_path / "K"
    assert main(["check", str(definition), "--keep", str(keep)]) == 1
    assert sorted(os.listdir(keep)) == ["g.md", "g.results.parquet", "g.summary.json"]
    # the new run's results: those the module's golden was written with, not the swapped ones
    assert pq.read_table(keep / "g.results.parquet").equals(
        pq.read_table(golden / "small.results.parquet")
    )
    assert "2 scenarios flipped" in (keep / "g.md").read_text()


def test_the_significant_rule_names_the_flips_and_passes_a_balanced_change(
    golden, tmp_path, capsys
):
    definition, became_ok, became_failed = _swap_two(golden, tmp_path, strict=False)
    capsys.readouterr()
    assert main(["check", str(definition)]) == 0
    out = capsys.readouterr().out
    assert (
        f"within tolerance (significant): ok->failed 1 ({became_failed}), "
        f"failed->ok 1 ({became_ok})"
        in out
    )
    assert main(["check", str(definition), "--update"]) == 0  # the results follow the code again
    assert pq.read_table(definition.with_name("g.results.parquet")).equals(
        pq.read_table(golden / "small.results.parquet")
    )
    capsys.readouterr()
    assert main(["check", str(definition)]) == 0
    assert "matches" in capsys.readouterr().out


def test_the_verdict_says_the_drop_it_detects_and_warns_below_success_drop_pct(
    golden, tmp_path, capsys
):
    (tmp_path / "g.toml").write_text(DEFINITION + "\n[tolerance]\nsuccess_drop_pct = 10\n")
    for suffix in (".summary.json", ".results.parquet"):
        shutil.copy(golden / f"small{suffix}", tmp_path / f"g{suffix}")
    detects = (
        f"detects drops of {power.points_text(power.detectable_drop_pct(20, 0))} points or more "
        "at 80 % power (20 scenarios, alpha 0.05)"
    )
    warning = (
        "warning: success_drop_pct 10 is below the detectable drop ("
        f"{power.points_text(power.detectable_drop_pct(20, 0))} points at 80 % power with 20 "
        f"scenarios): about {power.scenarios_to_detect(10, 0.0)} scenarios would detect a "
        "10-point drop"
    )
    executor = make_executor("local", 2)
    try:
        outcome = check_sweep(str(tmp_path / "g.toml"), executor)
    finally:
        executor.close()
    assert outcome.status == "match"  # a warning fails nothing
    assert outcome.summary == f"matches; {detects}; {warning}"
    assert f"\n  {detects}\n" in outcome.report and f"\n  {warning}\n" in outcome.report
    (tmp_path / "strict").mkdir()
    definition, _, _ = _swap_two(golden, tmp_path / "strict", strict=True)
    capsys.readouterr()
    assert main(["check", str(definition), "-v"]) == 1
    strict = "detects a drop of one flip, 5.0 points (20 scenarios; strict: any flip fails)"
    out = capsys.readouterr().out
    assert f"\n  {strict}\n" in out and f"; {strict}\n" in out  # the report, the verdict


def test_a_golden_without_results_checks_by_its_summary(golden, tmp_path, capsys):
    shutil.copy(golden / "small.toml", tmp_path / "old.toml")
    summary = json.loads((golden / "small.summary.json").read_text())
    summary["placement_error_mm"]["p50"] += 0.7
    (tmp_path / "old.summary.json").write_text(json.dumps(summary))
    capsys.readouterr()
    assert main(["check", str(tmp_path / "old.toml")]) == 1
    out = capsys.readouterr().out
    assert "placement_error_mm.p50 moved -0.700 mm" in out
    assert "judged by its summary only (no old.results.parquet)" in out
    assert not (tmp_path / "old.results.parquet").exists()


def test_another_seed_or_a_bad_results_file_is_named(golden, tmp_path, capsys):
    definition, _, _ = _swap_two(golden, tmp_path, strict=False)
    definition.write_text(DEFINITION.replace("seed = 3", "seed = 4"))
    capsys.readouterr()
    assert main(["check", str(definition)]) == 1
    assert (
        "the definition's seed 4 is not the one of g.results.parquet (3)" in capsys.readouterr().out
    )
    definition.write_text(DEFINITION)
    (tmp_path / "g.results.parquet").write_text("not parquet")
    assert main(["check", str(definition)]) == 2
    out = capsys.readouterr().out
    assert "g.results.parquet' cannot be read as Parquet" in out and "Traceback" not in out
    for column, values, message in (
        ("scenario", [str(i) for i in range(20)], "column 'scenario' row 1 holds '0'"),
        ("outcome", ["banana"] * 20, "column 'outcome' row 1 holds 'banana'"),
        ("placement_error_mm", [float("-inf")] * 20, "column 'placement_error_mm' row 1"),
    ):
        table = pq.read_table(golden / "small.results.parquet")
        table = table.set_column(table.column_names.index(column), column, pa.array(values))
        meta = pq.read_schema(golden / "small.results.parquet").metadata
        pq.write_table(table.replace_schema_metadata(meta), tmp_path / "g.results.parquet")
        assert main(["check", str(definition)]) == 2
        out = capsys.readouterr().out
        assert "g.results.parquet' " + message in out and "Traceback" not in out, out


def test_the_paired_verdict_is_the_same_whatever_the_executor(golden, tmp_path):
    definition, _, _ = _swap_two(golden, tmp_path, strict=True)
    outcomes = []
    for name, jobs in (("local", 1), ("local", 2), ("dask", 2)):
        executor = make_executor(name, jobs)
        try:
            outcomes.append(check_sweep(str(definition), executor))
        finally:
            executor.close()
    assert {o.status for o in outcomes} == {"differ"}
    assert len({o.summary for o in outcomes}) == 1 and len({o.report for o in outcomes}) == 1


def test_the_html_report_of_a_differing_sweep_golden_shows_its_flips_and_map(golden, tmp_path,
                                                                            capsys):
    definition, _, _ = _swap_two(golden, tmp_path, strict=True)
    capsys.readouterr()
    assert main(["check", str(definition), "--html", str(tmp_path / "p.html")]) == 1
    page = (tmp_path / "p.html").read_text()
    assert "twin check: 1 differ" in page and "<h3>flips</h3>" in page
    assert page.count("<td>ok -&gt; failed</td>") + page.count("<td>failed -&gt; ok</td>") == 2
    assert "McNemar's exact p = " in page and "Newcombe's paired 95 % interval" in page
    assert 'src="data:image/png;base64,' in page  # the success map, inline
