"""The task's identity in `task_start` is set apart from what the task says (compare.identity)."""

from __future__ import annotations

import pytest

from twin.compare.identity import is_identity, set_identity_apart
from twin.model.types import Command

SHA_A, SHA_B = "sha256:" + "a" * 64, "sha256:" + "b" * 64


def _start(message: object, **data) -> Command:
    return Command(0, "event", {"kind": "task_start", "body": "", "message": message, "data": data})


@pytest.mark.parametrize(
    ("message", "identity"),
    [
        (SHA_A, True),  # this release: the source's sha256
        ("twin.tasks.pick_place", True),  # 2ffeb44: a built-in task's module
        ("twin_user_task_carry", True),  # 2ffeb44: a task file's module
        ("my_tasks.make.<locals>.run", True),  # a function without a source file
        ("sha256:abc", False),
        ("hello world", False),
        ("cycle 1: placed", False),
        (None, False),
    ],
)
def test_what_counts_as_a_task_identity(message, identity):
    assert is_identity(message) is identity


def test_only_the_identity_of_a_task_start_is_set_apart():
    said, diffs = set_identity_apart([_start(SHA_A, cycles=1)], [_start(SHA_B, cycles=2)], False)
    # the identity made the golden's; the parameters left to differ
    assert said[0].args["message"] == SHA_A and said[0].args["data"] == {"cycles": 2}
    assert [(d.index, d.cause, d.judged) for d in diffs] == [(0, "task source changed", False)]
    _, diffs = set_identity_apart([_start("twin.tasks.pick_place")], [_start(SHA_B)], False)
    assert diffs[0].cause == "recorded by an earlier release"


def test_exact_judges_the_identity():
    said, diffs = set_identity_apart([_start(SHA_A)], [_start(SHA_B)], True)
    assert said[0].args["message"] == SHA_B and diffs[0].judged


def test_free_text_and_other_annotations_are_what_a_task_says():
    said, diffs = set_identity_apart([_start("hello world")], [_start(SHA_B)], False)
    assert said[0].args["message"] == SHA_B and not diffs
    placed = Command(9, "event", {"kind": "placed", "body": "box", "message": "twin.a"})
    other = Command(9, "event", {**placed.args, "message": "twin.b"})
    said, diffs = set_identity_apart([placed], [other], False)
    assert said == [other] and not diffs


def _placed(message: str, error_m: float, step: int = 9) -> Command:
    args = {"kind": "placed", "body": "box", "message": message}
    return Command(step, "event", {**args, "data": {"cycle": 1, "error_m": error_m}})


def test_an_earlier_release_s_wording_is_excused_but_not_its_numbers_or_steps():
    """A golden of 2ffeb44 worded `placed` '0.00 mm' where this release says '0.000 mm': the
    message is taken as the golden's; its data, step, kind and body still compare."""
    golden = [_start("twin.tasks.pick_place"), _placed("placed 0.00 mm", 1e-7)]
    now = [_start(SHA_B), _placed("placed 0.000 mm", 2e-3, step=10)]
    said, diffs = set_identity_apart(golden, now, False)
    assert said[1].args["message"] == "placed 0.00 mm"
    assert said[1].args["data"]["error_m"] == 2e-3 and said[1].step == 10
    assert diffs[0].reworded == 1 and "1 other annotation message worded" in diffs[0].describe()
    # a source edited in this release: what the task says is judged as it is worded
    said, diffs = set_identity_apart([_start(SHA_A), golden[1]], now, False)
    assert said[1].args["message"] == "placed 0.000 mm" and diffs[0].reworded == 0
    # exact judges everything
    said, diffs = set_identity_apart(golden, now, True)
    assert said == now and diffs[0].reworded == 0
