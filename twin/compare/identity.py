"""The task's identity in `task_start`, judged apart from what the task says.

A task run says `task_start` first, and its message names the task: now the sha256 of its
source file (`sha256:<hex>`, twin.tasks.task_identity); releases up to 2ffeb44 wrote the task's
module instead (`twin.tasks.pick_place`, `twin_user_task_carry` for a file `carry.py`). So an
edited comment changes that message, and so does an upgrade, while the robot does exactly the
same. Only a tolerance of 0 on commands.annotations (`--tolerance exact`) judges the identity;
every other verdict excuses it, with a note, and judges the rest of task_start (its step, its
parameters) and every other annotation as before.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

from twin.model.types import Command

EARLIER_RELEASE = "recorded by an earlier release"
_SHA = re.compile(r"sha256:[0-9a-f]{64}")
# a module (an earlier release), or module.qualname (a task function without a source file)
_NAME = re.compile(r"[A-Za-z_]\w*(\.(<locals>|[A-Za-z_]\w*))*")


@dataclass(frozen=True)
class IdentityDifference:
    """One task_start whose identity alone differs: annotation #index at step, as each run names
    the task; judged: the verdict counts it (a tolerance of 0 on commands.annotations)."""

    index: int
    step: int
    golden: str
    candidate: str
    judged: bool
    reworded: int = 0  # other annotations whose message the earlier release worded otherwise

    @property
    def cause(self) -> str:
        g, c = (bool(_SHA.fullmatch(x)) for x in (self.golden, self.candidate))
        if g and c:
            return "task source changed"
        if c:
            return EARLIER_RELEASE
        if g:
            return "the candidate was recorded by an earlier release"
        return "the task is named otherwise"

    def describe(self) -> str:
        text = (
            f"task_start names the task {_short(self.golden)} in the golden, "
            f"{_short(self.candidate)} in the candidate"
        )
        if self.reworded:
            text += (
                f"; {self.reworded} other annotation message{'s' if self.reworded > 1 else ''} "
                "worded as that release did (their kind, step and data compared)"
            )
        return text


def is_identity(message: object) -> bool:
    """Whether a task_start message is a task's identity, as some release wrote it."""
    return isinstance(message, str) and bool(_SHA.fullmatch(message) or _NAME.fullmatch(message))


def set_identity_apart(
    golden: list[Command], candidate: list[Command], judged: bool
) -> tuple[list[Command], list[IdentityDifference]]:
    """The candidate's annotations, with the identity of each task_start paired (by index, as the
    annotations are) with a golden task_start of another identity made the golden's, unless
    judged; and those differences. Nothing else of a task_start changes: its step, body and
    parameters compare as before. A golden an earlier release recorded also worded what its task
    said in that release's words: then every annotation's message is the golden's too (its kind,
    body, step and data still compare)."""
    out, diffs = list(candidate), []
    for i, (g, c) in enumerate(zip(golden, candidate, strict=False)):
        if not (_task_start(g) and _task_start(c)):
            continue
        a, b = g.args.get("message"), c.args.get("message")
        if a == b or not (is_identity(a) and is_identity(b)):
            continue
        diffs.append(IdentityDifference(i, g.step, a, b, judged))
        if not judged:
            out[i] = dataclasses.replace(c, args={**c.args, "message": a})
    if not judged and any(d.cause == EARLIER_RELEASE for d in diffs):
        out, reworded = _messages_as_the_golden_words_them(golden, out)
        diffs = [dataclasses.replace(d, reworded=reworded) for d in diffs]
    return out, diffs


def _messages_as_the_golden_words_them(
    golden: list[Command], candidate: list[Command]
) -> tuple[list[Command], int]:
    """candidate with each annotation's message replaced by the golden's where the two are the
    same annotation (index, kind and body) worded otherwise; and how many were."""
    out, reworded = list(candidate), 0
    for i, (g, c) in enumerate(zip(golden, candidate, strict=False)):
        same = (g.args.get("kind"), g.args.get("body")) == (c.args.get("kind"), c.args.get("body"))
        if same and not _task_start(g) and g.args.get("message") != c.args.get("message"):
            out[i] = dataclasses.replace(c, args={**c.args, "message": g.args.get("message")})
            reworded += 1
    return out, reworded


def identity_notes(
    diffs: list[IdentityDifference], *, match: bool, bit_identical: bool
) -> list[str]:
    """The report's note on each identity difference: why it differs, and whether the verdict
    counted it (match: the verdict; bit_identical: every frame field bit for bit the same)."""
    notes = []
    for d in diffs:
        if d.judged:
            notes.append(
                f"{d.cause}: {d.describe()}; a tolerance of 0 on commands.annotations (exact) "
                "judges the task's identity, the other presets leave it out"
            )
        elif match:
            how = "bit for bit" if bit_identical else "within the verdict"
            notes.append(f"{d.cause}, behaviour identical ({how}): {d.describe()}")
        else:
            notes.append(f"{d.cause} (not judged; the differences reported are others): "
                         f"{d.describe()}")
    return notes


def identity_summary(diffs: list[IdentityDifference], match: bool) -> str:
    """What a one-line summary of a match adds ("; recorded by an earlier release, behaviour
    identical"), or ""."""
    causes = dict.fromkeys(d.cause for d in diffs if not d.judged)
    return "".join(f"; {c}, behaviour identical" for c in causes) if match else ""


def _task_start(c: Command) -> bool:
    return c.kind == "event" and c.args.get("kind") == "task_start"


def _short(identity: str) -> str:
    if _SHA.fullmatch(identity):
        return f"by its source's sha256 {identity[7:19]}..."
    return f"{identity!r}"
