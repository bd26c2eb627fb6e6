"""`twin sweep compare A B` on real result folders: a paired report where the scenarios are the same
ones (counts checked against the two results.parquet files directly), Newcombe's unpaired interval
where the seeds differ, --report Markdown or JSON, --fail-if-worse, and the pictures (--plot,
`twin sweep plot`), with one line and exit 2 when matplotlib is missing."""

from __future__ import annotations

import json
import math
import re
import sys

import pyarrow.parquet as pq
import pytest

from twin.cli.main import main
from twin.sweep.stats import mcnemar_exact, newcombe_unpaired

SWEEP = [
    "pick_place",
    "--scenarios",
    "24",
    "--seed",
    "5",
    "--vary",
    "box.x_m=normal(0.2,0.012)",
    "--vary",
    "box.y_m=normal(0.7,0.012)",
    "--param",
    "cycles=1",
    "--param",
    "pause_s=0.1",
    "--save",
    "none",
    "--quiet",
    "--jobs",
    "2",
]
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A: placements within 30 mm pass; B: the same scenarios, within 12 mm (many go ok -> failed);
    C: A's definition with another seed."""
    folder = tmp_path_factory.mktemp("compare")
    assert (
        main(["sweep", *SWEEP, "--param", "max_error_m=0.03", "--out", str(folder / "a"), "--plot"])
        == 0
    )
    assert main(["sweep", *SWEEP, "--param", "max_error_m=0.012", "--out", str(folder / "b")]) == 0
    seed6 = [("6" if a == "5" else a) for a in SWEEP]
    assert main(["sweep", *seed6, "--param", "max_error_m=0.03", "--out", str(folder / "c")]) == 0
    return folder


def _outcomes(folder):
    return {
        r["scenario"]: r["outcome"] == "ok"
        for r in pq.read_table(
            folder / "results.parquet", columns=["scenario", "outcome"]
        ).to_pylist()
    }


def test_a_paired_report_counts_the_flips_of_the_two_folders(runs, tmp_path, capsys):
    a, b = _outcomes(runs / "a"), _outcomes(runs / "b")
    worse = sorted(i for i in a if a[i] and not b[i])
    better = sorted(i for i in a if b[i] and not a[i])
    assert worse and not better  # a tighter acceptance only fails more
    capsys.readouterr()
    assert (
        main(
            [
                "sweep",
                "compare",
                str(runs / "a"),
                str(runs / "b"),
                "--report",
                str(tmp_path / "r.json"),
                "--plot",
                str(tmp_path / "c.png"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "definitions differ in: params.max_error_m 0.03 -> 0.012" in out
    assert "paired on 24 scenarios" in out and f"ok->failed {len(worse)}, failed->ok 0" in out
    assert f"twin sweep {runs / 'b' / 'sweep.toml'} --only {worse[0]} --out runs/s{worse[0]}" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["kind"] == "paired" and report["ok_to_failed"] == len(worse)
    assert [s["scenario"] for s in report["ok_to_failed_scenarios"]] == worse
    assert report["mcnemar_exact_p"] == mcnemar_exact(len(worse), 0)
    lo, hi = report["newcombe_paired95"]
    assert lo <= report["difference"] == -len(worse) / 24 <= hi
    assert (tmp_path / "c.png").read_bytes().startswith(PNG)
    assert (runs / "a" / "sweep.png").read_bytes().startswith(PNG)  # twin sweep --plot
    code = main(
        [
            "sweep",
            "compare",
            str(runs / "a"),
            str(runs / "b"),
            "--fail-if-worse",
            "--report",
            str(tmp_path / "r.md"),
        ]
    )
    err = capsys.readouterr().err
    assert mcnemar_exact(len(worse), 0) < 0.05 and code == 1  # 16 of 24 go ok -> failed
    assert err.startswith("twin: error: ") and "is worse than" in err and err.count("\n") == 1
    markdown = (tmp_path / "r.md").read_text()
    assert markdown.startswith("# Paired comparison") and "| McNemar exact p |" in markdown


def test_another_seed_is_compared_unpaired(runs, tmp_path, capsys):
    a, c = _outcomes(runs / "a"), _outcomes(runs / "c")
    capsys.readouterr()
    assert (
        main(
            [
                "sweep",
                "compare",
                str(runs / "a"),
                str(runs / "c"),
                "--report",
                str(tmp_path / "u.json"),
            ]
        )
        == 0
    )
    assert "not paired (seeds differ: 5 and 6)" in capsys.readouterr().out
    report = json.loads((tmp_path / "u.json").read_text())
    assert report["kind"] == "unpaired"
    expected = newcombe_unpaired(sum(c.values()), 24, sum(a.values()), 24)
    assert report["newcombe_unpaired95"] == list(expected)


def test_sweep_plot_and_bad_input(runs, tmp_path, capsys, monkeypatch):
    capsys.readouterr()
    assert main(["sweep", "plot", str(runs / "b"), "--out", str(tmp_path / "b.png")]) == 0
    assert "(axes: box." in capsys.readouterr().out
    assert (tmp_path / "b.png").read_bytes().startswith(PNG)
    for args, message in (
        ([str(runs / "a"), str(tmp_path / "none")], "is neither a result folder"),
        (
            [str(runs / "a"), str(runs / "b"), "--report", "r.txt"],
            "--report 'r.txt' is invalid; expected a file ending in .md or .json",
        ),
        ([str(runs / "a")], "the following arguments are required: B"),
    ):
        assert main(["sweep", "compare", *args]) == 2
        err = capsys.readouterr().err
        assert err.startswith("twin: error: ") and message in err and err.count("\n") == 1
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    assert main(["sweep", "plot", str(runs / "a"), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "--plot needs matplotlib, which is not installed" in err and err.count("\n") == 1
    assert (
        main(["sweep", *SWEEP, "--out", str(tmp_path / "never"), "--plot"]) == 2
    )  # before it runs
    capsys.readouterr()
    assert not (tmp_path / "never" / "results.parquet").exists()


def _tampered(runs, tmp_path, name: str, change) -> str:
    """A copy of folder b whose results.parquet `change` rewrote (table -> table)."""
    import shutil

    folder = tmp_path / name
    shutil.copytree(runs / "b", folder)
    table = pq.read_table(folder / "results.parquet")
    pq.write_table(change(table), folder / "results.parquet")
    return str(folder)


def _column(table, name, values):
    import pyarrow as pa

    return table.set_column(table.column_names.index(name), name, pa.array(values))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda t: _column(t, "scenario", [str(i) for i in range(t.num_rows)]),
         "column 'scenario' row 1 holds '0'; expected whole numbers"),
        (lambda t: _column(t, "outcome", ["ok"] * 5 + ["banana"] * (t.num_rows - 5)),
         "column 'outcome' row 6 holds 'banana'; expected one of ok, error"),
        (lambda t: _column(t, "placement_error_mm", [1.0, -math.inf] + [1.0] * (t.num_rows - 2)),
         "column 'placement_error_mm' row 2 holds -inf; expected a finite number"),
        (lambda t: _column(t, "placement_error_mm", [float("nan")] * t.num_rows),
         "column 'placement_error_mm' row 1 holds nan"),
        (lambda t: _column(t, "scenario", [0] + list(range(t.num_rows - 1))),
         "column 'scenario': scenario 0 is in two rows"),
        (lambda t: _column(t, "box.x_m", [v + 0.01 for v in t.column("box.x_m").to_pylist()]),
         "column 'box.x_m': scenario 0 has another value than in"),
    ],
)
def test_a_bad_results_file_is_one_line_naming_file_column_and_row(
    runs, tmp_path, capsys, change, message
):
    bad = _tampered(runs, tmp_path, "bad", change)
    capsys.readouterr()
    assert main(["sweep", "compare", str(runs / "a"), bad]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error: results ") and err.count("\n") == 1, err
    assert message in err and "bad" in err, err
def test_compare_html_shows_the_flips_the_interval_and_the_map(runs, tmp_path, capsys):
    a, b = _outcomes(runs / "a"), _outcomes(runs / "b")
    worse = sorted(i for i in a if a[i] and not b[i])
    page_path = tmp_path / "c.html"
    assert main(["sweep", "compare", str(runs / "a"), str(runs / "b"), "--html",
                 str(page_path)]) == 0
    assert f"wrote {page_path}" in capsys.readouterr().out
    page = page_path.read_text()
    assert "<title>twin sweep compare</title>" in page
    rows = re.findall(r"<tr><td>(\d+)</td><td>ok -&gt; failed</td>", page)
    assert [int(s) for s in rows] == worse[: len(rows)] and rows  # the flips table
    assert f"McNemar's exact p = {mcnemar_exact(len(worse), 0):.3g}" in page
    assert "Newcombe's paired 95 % interval [" in page
    assert "<img alt=\"success map\"" in page and "src=\"data:image/png;base64," in page
    assert not re.search(r"(src|href)\s*=\s*[\"']?(https?:)?//", page)
    assert main(["sweep", "compare", str(runs / "a"), str(runs / "b"), "--html", "c.htm"]) == 2
    assert "--html 'c.htm' should end in .html" in capsys.readouterr().err
