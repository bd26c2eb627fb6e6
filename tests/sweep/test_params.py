"""`twin run --param`: task parameters checked against the task function's signature and recorded,
so `twin check` re-runs them; an unknown one (also `--cycles` for a task without cycles) is exit 2."""

from __future__ import annotations

from twin.cli.main import main
from twin.record.mcap.reader import load


def test_param_values_are_json_when_they_parse_and_are_recorded(tmp_path, capsys):
    out = tmp_path / "p.mcap"
    assert main(["run", "pick_place", "--param", "cycles=1", "--param", "pause_s=0.25", "--param", "box=box",
                 "--record", str(out)]) == 0
    assert load(out).run["params"] == {"cycles": 1, "pause_s": 0.25, "box": "box"}
    capsys.readouterr()
    assert main(["check", str(out)]) == 0  # the stored params re-run the same task


def test_unknown_params_are_one_line_exit_2(capsys):
    assert main(["run", "pick_place", "--param", "speed=2", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert err == ("twin: error: task 'pick_place' takes no parameter 'speed'; its parameters: cycles, pause_s, "
                   "box, keep_going, max_error_m\n")
    assert main(["run", "seed002", "--robot", "seed002", "--cycles", "3", "--no-record"]) == 2
    assert capsys.readouterr().err == "twin: error: task 'seed002' takes no parameter 'cycles'; its parameters: none\n"
    assert main(["run", "pick_place", "--cycles", "1", "--param", "cycles=2", "--no-record"]) == 2
    assert "--cycles and --param cycles" in capsys.readouterr().err
    assert main(["run", "pick_place", "--param", "=1", "--no-record"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_cycles_default_still_reaches_tasks_that_take_it(tmp_path):
    out = tmp_path / "s.mcap"
    assert main(["run", "seed002", "--robot", "seed002", "--record", str(out)]) == 0
    assert load(out).run["params"] == {}
    assert main(["run", "pick_place", "--record", str(out)]) == 0
    assert load(out).run["params"] == {"cycles": 2}
