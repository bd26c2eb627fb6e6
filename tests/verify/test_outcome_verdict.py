"""The `outcome` verdict never passes a broken run: a file cut short (also once recovered) is
`unfinished`, and cycles a task let fail under keep_going are counted."""

from __future__ import annotations

import shutil

from twin import load
from twin.cli.main import main


def test_a_cut_and_recovered_run_does_not_pass_outcome(tmp_path, capsys):
    whole = tmp_path / "whole.mcap"
    assert main(["run", "pick_place", "--cycles", "2", "--record", str(whole)]) == 0
    cut = tmp_path / "cut.mcap"
    data = whole.read_bytes()
    # the footer and the finalization record are gone
    cut.write_bytes(data[:int(len(data) * 0.999)])
    assert main(["recover", str(cut), "-o", str(tmp_path / "fixed.mcap")]) == 0
    fixed = load(str(tmp_path / "fixed.mcap"))
    assert fixed.outcome == "unfinished" and len(fixed.frames) > 0.9 * len(load(str(whole)).frames)
    assert load(str(whole)).outcome == "ok"
    capsys.readouterr()
    assert main(["diff", str(whole), str(tmp_path / "fixed.mcap"), "--tolerance", "outcome"]) == 1
    out = capsys.readouterr().out
    assert "MISMATCH" in out and "outcome.task" in out and "unfinished" in out


def test_failed_cycles_under_keep_going_do_not_pass_outcome(tmp_path, capsys):
    golden, candidate = tmp_path / "golden.mcap", tmp_path / "candidate.mcap"
    args = ["run", "pick_place", "--cycles", "2", "--param", "keep_going=true"]
    assert main([*args, "--record", str(golden)]) == 0
    # goes on: exit 0
    assert main([*args, "--param", "max_error_m=1e-9", "--record", str(candidate)]) == 0
    assert sum(e.kind == "cycle_failed" for e in load(str(candidate)).events) == 2
    capsys.readouterr()
    assert main(["diff", str(golden), str(candidate), "--tolerance", "outcome"]) == 1
    assert (
        "first divergence: step" in (out := capsys.readouterr().out)
        and "counts.cycle_failed" in out
    )
    shutil.copyfile(golden, tmp_path / "same.mcap")
    assert main(["diff", str(golden), str(tmp_path / "same.mcap"), "--tolerance", "outcome"]) == 0
