"""A task is named by its content, and what a task says is judged apart from what the robot does."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.conftest import FIXTURES, ROOT
from tests.support.cli import twin, twin_child
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
    # the built-in task by name, run here: what `exact` compares with (another libm makes other
    # last bits than the committed golden's, so exact on GOLDEN would judge the machine)
    assert main(["run", "pick_place", "--record", str(d / "byname.mcap")]) == 0
    return d


def test_the_task_is_named_by_its_content_with_line_ends_made_lf(tmp_path):
    assert task_identity(pick_place.run) == "sha256:" + source_sha256(pick_place.__file__)
    lf, crlf = tmp_path / "lf.py", tmp_path / "crlf.py"
    lf.write_bytes(b"def run(twin):\n    pass\n")
    crlf.write_bytes(b"def run(twin):\r\n    pass\r\n")
    assert source_sha256(lf) == source_sha256(crlf)
    assert source_sha256(lf) != source_sha256(GOLDEN)


def test_a_renamed_copy_of_a_task_is_the_same_task_even_under_exact(runs, capsys):
    byname = runs / "byname.mcap"
    code, out, _ = twin(capsys, "diff", byname, runs / "renamed.mcap", "--tolerance", "exact")
    assert code == 0, out
    assert out.startswith("MATCH")
    # the name stays visible, as configuration
    assert "run.task 'pick_place' -> 'renamed.py'" in out


def test_an_edited_comment_is_an_annotation_difference_and_not_a_physical_one(runs, capsys):
    byname = runs / "byname.mcap"
    code, out, _ = twin(capsys, "diff", byname, runs / "commented.mcap", "--tolerance", "exact")
    assert code == 1
    assert "first divergence: step 0 (t = 0.000000 s): commands.annotations [#0 task_start]" in out
    assert "annotations only: the runs do not diverge physically" in out
    code, out, _ = twin(capsys, "diff", byname, runs / "commented.mcap", "--tolerance", "exact",
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


@pytest.fixture
def carry(tmp_path, capsys) -> Path:
    """A user's task file (the one kept with the 2ffeb44 goldens) recorded by this release into
    goldens/carry.mcap beside it."""
    shutil.copy(FIXTURES / "release_2ffeb44" / "carry.py", tmp_path / "carry.py")
    (tmp_path / "goldens").mkdir()
    code, out, err = twin(capsys, "run", tmp_path / "carry.py", "--param", "hold_s=0.2",
                          "--record", tmp_path / "goldens" / "carry.mcap")
    assert code == 0, out + err
    return tmp_path


def test_a_comment_added_to_a_task_file_passes_every_preset_but_exact(carry, capsys):
    task = carry / "carry.py"
    task.write_text(task.read_text() + "# one comment more: the same motion\n")
    for preset, expected in (("noise", 0), ("tight", 0), ("exact", 1)):
        code, out, _ = twin(capsys, "check", "-v", "--tolerance", preset, carry / "goldens")
        assert code == expected, (preset, out)
        if expected == 0:
            assert "bit-identical; task source changed, behaviour identical" in out, out
        else:
            assert "first divergence: step 0 (t = 0.000000 s): commands.annotations [#0 task" in out
            assert "note: task source changed: task_start names the task by its source's " in out


def test_any_other_annotation_change_still_fails(carry, capsys):
    """A renamed phase is what the task says, not who it is: red under the default preset, the
    identity set apart in a note."""
    task = carry / "carry.py"
    task.write_text(task.read_text().replace('twin.phase("place")', 'twin.phase("put")'))
    code, out, _ = twin(capsys, "check", "-v", carry / "goldens")
    assert code == 1
    assert "changed at step 1326 (commands.annotations)" in out, out
    assert "commands.annotations [#2 phase]" in out, out
    assert "note: task source changed (not judged; the differences reported are others)" in out


@pytest.mark.slow  # seconds: a copy of the package, `twin check` twice in child processes
def test_a_comment_added_to_the_built_in_pick_place_passes_every_preset_but_exact(tmp_path):
    """`twin/tasks/pick_place.py` with a comment more, in a copy of the package (first on the
    child's sys.path: its working directory), checks recordings/pick_place_mtb.mcap green under
    noise and tight (the built-in task is resolved by name), and red under exact."""
    shutil.copytree(ROOT / "twin", tmp_path / "twin", ignore=shutil.ignore_patterns("__pycache__"))
    task = tmp_path / "twin" / "tasks" / "pick_place.py"
    task.write_text(task.read_text() + "\n# one comment more: the same motion\n")
    shutil.copy(GOLDEN, tmp_path / GOLDEN.name)
    for preset in ("noise", "tight"):
        done = twin_child("check", "--tolerance", preset, GOLDEN.name, cwd=tmp_path)
        assert done.returncode == 0, done.stdout + done.stderr
        # bit-identical here; within the noise floor on another libm
        assert "; task source changed, behaviour identical\n" in done.stdout
    done = twin_child("check", "-v", "--tolerance", "exact", GOLDEN.name, cwd=tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "note: task source changed: task_start names the task" in done.stdout


@pytest.mark.parametrize(("error_m", "limit_m", "text"), [
    (1.2e-5, 1e-5, "0.012"),  # 3 decimals (µm) are enough
    (1.0004e-5, 1e-5, "0.0100040"),  # more, until the figure reads larger than the limit
    (3.1e-3, 2e-3, "3.100"),
])
def test_a_placement_beyond_its_limit_never_reads_as_equal_to_it(error_m, limit_m, text):
    assert mm_beyond(error_m, limit_m).rstrip("0") == text.rstrip("0")
    assert float(mm_beyond(error_m, limit_m)) > limit_m * 1000
