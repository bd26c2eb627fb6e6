"""The commands and the annotations, entry by entry, and which golden command likely caused a
divergence (the last one before it that acts on its field)."""

from __future__ import annotations

from twin.compare.allowances import Allowances
from twin.compare.identity import IdentityDifference, set_identity_apart
from twin.compare.noise import command_number_difference
from twin.compare.result import Divergence, FieldStat
from twin.compare.tolerances import INF
from twin.model.recording import Recording
from twin.model.types import Command


def _command_text(c: Command) -> str:
    args = ", ".join(f"{k}={v!r}" for k, v in sorted(c.args.items()))
    return f"step {c.step} {c.kind}({args})"


def _split_annotations(commands: list[Command]) -> tuple[list[Command], list[Command]]:
    """(commands that act, annotations): an `event` Command acts on nothing, so the two sequences
    are paired apart and an extra annotation does not shift the pairing of the commands that act."""
    return [c for c in commands if c.kind != "event"], [c for c in commands if c.kind == "event"]


def command_stats(
    golden: Recording, candidate: Recording, allow: Allowances, dt_ns: int
) -> tuple[list[FieldStat], list[IdentityDifference]]:
    """The commands that act (commands.sequence) and the annotations (commands.annotations), each
    paired apart; and the task identities set apart from the annotations (twin.compare.identity)."""
    g_acts, g_said = _split_annotations(golden.commands)
    c_acts, c_said = _split_annotations(candidate.commands)
    said, identities = set_identity_apart(g_said, c_said, allow.identity_judged)
    stats = [
        _command_stat(
            g=g, c=c, name=name, tolerance=t, dt_ns=dt_ns, until_step=allow.commands_until
        )
        for name, g, c, t in (
            ("commands.sequence", g_acts, c_acts, allow.commands),
            ("commands.annotations", g_said, said, allow.annotations),
        )
    ]
    return stats, identities


def _command_stat(
    *,
    g: list[Command],
    c: list[Command],
    name: str,
    tolerance: float,
    dt_ns: int,
    until_step: int | None,
) -> FieldStat:
    """Two command sequences, entry by entry: step, kind and text exactly, the numbers in their
    arguments within tolerance (0: equal; inf: the field is off); entries from until_step on are not
    judged."""
    if until_step is not None:
        g, c = [x for x in g if x.step < until_step], [x for x in c if x.step < until_step]
    n = max(len(g), len(c))
    differing = [
        i
        for i in range(n)
        if i >= len(g) or i >= len(c) or not _commands_agree(g[i], c[i], tolerance)
    ]
    first_i = differing[0] if differing else -1
    step = -1 if first_i < 0 else min(x[first_i].step for x in (g, c) if first_i < len(x))
    stat = FieldStat(
        name=name,
        unit="",
        tolerance=tolerance,
        worst=float(len(differing)),
        worst_step=step,
        worst_element="",
        rms=float(len(differing)),
        steps_over=len(differing) if tolerance != INF else 0,
    )
    if differing and tolerance != INF:
        expected = [_command_text(g[first_i]) if first_i < len(g) else None]
        actual = [_command_text(c[first_i]) if first_i < len(c) else None]
        command = g[first_i] if first_i < len(g) else c[first_i]
        kind = command.args.get("kind", "event") if command.kind == "event" else command.kind
        stat.first = Divergence(
            step=step,
            t_s=step * dt_ns * 1e-9,
            channel="commands",
            field=name.split(".")[1],
            element=f"#{first_i} {kind}",
            expected=expected,
            actual=actual,
            difference=float(len(differing)),
            tolerance=tolerance,
            unit="",
        )
    return stat


def _commands_agree(a: Command, b: Command, tolerance: float) -> bool:
    if tolerance == 0:
        return a == b
    d = command_number_difference(a, b)
    return d is not None and d <= tolerance


def on_path(command: Command, d: Divergence, joint_names: tuple[str, ...] | list[str]) -> bool:
    """Whether a command acts on the diverging field: a joint's command on that joint's fields, any
    joint, suction or key command on the pad, the hold and the objects; an annotation (`event`) on
    nothing."""
    if command.kind == "event":
        return False
    if d.channel == "joints":
        if command.kind == "key":
            return True
        joint = command.args.get("joint")
        if isinstance(joint, int) and not isinstance(joint, bool) and 0 <= joint < len(joint_names):
            joint = joint_names[joint]
        return command.kind.startswith("joint_") and joint == d.element
    return d.channel in (
        "suction",
        "hold",
        "pad",
        "objects",
        "final",
        "counts",
        "events",
        "outcome",
        "run",
        "images",
    )


def likely_cause(
    commands: list[Command], d: Divergence, joint_names: tuple[str, ...] | list[str] = ()
) -> str:
    """The golden's last command at or before the divergence that acts on the diverging field, or
    ""."""
    if d.channel == "commands":
        return ""
    before = [c for c in commands if c.step <= d.step and on_path(c, d, joint_names)]
    return _command_text(max(before, key=lambda c: c.step)) if before else ""
