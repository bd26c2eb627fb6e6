"""A task is named by its content, and what a task says is judged apart from what the robot does."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import ROOT
from tests.support.cli import twin
from twin.cli import main
from twin.tasks import pick_place, source_sha256, task_identity
from twin.tasks.pick_place import mm_beyond

GOLDEN = ROOT / "recordings" / "pick_place_mtb.mcap"  # pick_place, 2 cycles, robot mtb
SOURCE = Path(pick_place.__file__).read_text()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """pick_place run from a renamed copy, from a copy with one comment more, and from a copy that
    places the box 1 mm further in x."""
    d = tmp_path_factory.mktemp("identity")
    variants = {
        "renamed": SOURCE,
        "commented": SOURCE + "\n# one comment more: the same motion\n",
        "moved": SOURCE.replace("POINT_B_M = (-0.3, -0.55)", "POINT_B_M = (-0.299, -0.55)"),
    }
    assert variants["moved"] != SOURCE
    for name, text in variants.items():
        (d / f"{name}.py").write_text(text)
        assert main(["run", str(d / f"{name}.py"), "--record", str(d / f"{name}.mcap")]) == 0
    return d


def test_the_task_is_named_by_its_content_with_line_ends_made_lf(tmp_path):
    assert task_identity(pick_place.run) == "sha256:" + source_sha256(pick_place.__file__)
    lf, crlf = tmp_path / "lf.py", tmp_path / "crlf.py"
    lf.write_bytes(b"def run(twin):\n    pass\n")
    crlf.write_bytes(b"def run(twin):\r\n    pass\r\n")
    assert source_sha256(lf) == source_sha256(crlf)
    assert source_sha256(lf) != source_sha256(GOLDEN)


def test_a_renamed_copy_of_a_task_is_the_same_task_even_under_exact(runs, capsys):
    code, out, _ = twin(capsys, "diff", GOLDEN, runs / "renamed.mcap", "--tolerance", "exact")
    assert code == 0, out
    assert out.startswith("MATCH")
    # the name stays visible, as configuration
    assert "run.task 'pick_place' -> 'renamed.py'" in out


def test_an_edited_comment_is_an_annotation_difference_and_not_a_physical_one(runs, capsys):
    code, out, _ = twin(capsys, "diff", GOLDEN, runs / "commented.mcap", "--tolerance", "exact")
    assert code == 1
    assert "first divergence: step 0 (t = 0.000000 s): commands.annotations [#0 task_start]" in out
    assert "annotations only: the runs do not diverge physically" in out
    code, out, _ = twin(capsys, "diff", GOLDEN, runs / "commented.mcap", "--tolerance", "exact",
                        "--tol", "commands.annotations=inf")
    assert code == 0, out


def test_a_real_change_is_the_first_divergence_and_the_annotations_are_reported_apart(runs, capsys):
    code, out, _ = twin(capsys, "diff", GOLDEN, runs / "moved.mcap")
    assert code == 1
    first = next(line for line in out.splitlines() if line.startswith("first divergence:"))
    assert "commands.annotations" not in first and "step 0 " not in first, first
    # the task's identity is set apart (a note), what it says is not: the phase naming the point
    assert "note: task source changed (not judged; the differences reported are others)" in out
    also = "annotations differ too (apart from the physical divergence): step 774 "
    assert also + "(t = 3.225000 s): commands.annotations [#3 phase]" in out


@pytest.mark.parametrize(("error_m", "limit_m", "text"), [
    (1.2e-5, 1e-5, "0.012"),  # 3 decimals (µm) are enough
    (1.0004e-5, 1e-5, "0.0100040"),  # more, until the figure reads larger than the limit
    (3.1e-3, 2e-3, "3.100"),
])
def test_a_placement_beyond_its_limit_never_reads_as_equal_to_it(error_m, limit_m, text):
    assert mm_beyond(error_m, limit_m).rstrip("0") == text.rstrip("0")
    assert float(mm_beyond(error_m, limit_m)) > limit_m * 1000
