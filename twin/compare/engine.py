"""The diff engine: compare a candidate run with a golden one, field by field, in physical units.

Frames are aligned by step number (so a decimated golden compares with a full candidate); angles
are wrapped; orientations compare by the angle between quaternions; events pair by kind and body,
in order, within a window of steps. Commands (every input, kept at every step whatever the frame
rate) compare exactly, so a divergence between the kept frames of a decimated file still shows.
The outcome fields judge the result alone: the task ended ok, and how often the pad took and let go.
Everything is numpy over whole columns: no per-frame Python.
"""

from __future__ import annotations

from twin.compare.allowances import Allowances
from twin.compare.commands import command_stats, likely_cause
from twin.compare.events import EventDiff, match_events
from twin.compare.fields import align, frame_stats
from twin.compare.identity import identity_notes
from twin.compare.noise import NoiseFloor
from twin.compare.outcome import (
    count_stats,
    final_poses,
    final_stats,
    image_stat,
    length_stat,
    task_stat,
)
from twin.compare.result import DiffResult, Divergence, FieldStat, NotComparable, bit_identical
from twin.compare.tolerances import INF, Tolerances
from twin.model.errors import RecordingError
from twin.model.recording import Recording


# -- the engine --------------------------------------------------------------------------------
def comparable(golden: Recording, candidate: Recording) -> list[str]:
    """Why the two runs cannot be compared (empty when they can): structure, not names. Two robots
    with the same joints by role compare (a renamed profile or a longer link is a difference to
    report); another time step or another set of scene objects does not."""
    g, c = golden.config, candidate.config
    why = []
    if len(g.profile.joint_names) != len(c.profile.joint_names):
        why.append(
            f"the candidate's robot has {len(c.profile.joint_names)} joints, the golden's "
            f"{len(g.profile.joint_names)}"
        )
    if g.dt_ns != c.dt_ns:
        why.append(f"time step {c.dt_ns} ns differs from the golden's {g.dt_ns} ns")
    gn, cn = [o.name for o in g.objects], [o.name for o in c.objects]
    if sorted(gn) != sorted(cn):
        why.append(f"scene objects {cn} differ from the golden's {gn}")
    return why


def refuse_incomparable(golden: Recording, candidate: Recording, force: bool) -> list[str]:
    """NotComparable unless the runs compare (or force); with force, the notes on what was compared
    despite."""
    why = comparable(golden, candidate)
    if why and not force:
        raise NotComparable(
            "the runs are not comparable: " + "; ".join(why) + " (use --force to compare anyway)"
        )
    return [f"compared despite: {w}" for w in why]


def compare(
    golden: Recording,
    candidate: Recording,
    tolerances: Tolerances | None = None,
    *,
    force: bool = False,
    event_kinds: frozenset[str] | None = None,
    floor: NoiseFloor | None = None,
) -> DiffResult:
    """Compare candidate with golden; raises NotComparable for structurally different runs unless
    force.

    event_kinds: the event kinds to pair one by one (None: all). floor: the candidate's measured
    noise floor; each field then allows the larger of its tolerance and the floor at that step.
    """
    tol = tolerances or Tolerances()
    notes = refuse_incomparable(golden, candidate, force)
    _require_frames(golden, candidate)
    allow = Allowances.of(tol, floor)
    gi, ci = align(golden.frames.step, candidate.frames.step)
    dt_ns = golden.config.dt_ns
    length = (int(golden.frames.step[-1]), int(candidate.frames.step[-1]))
    finals = final_poses(golden, candidate, allow.scalar)
    commands, identities = command_stats(golden, candidate, allow, dt_ns)
    pictures, pictures_note = _pictures(golden, candidate, allow, dt_ns)
    fields = [
        *frame_stats(golden, candidate, gi, ci, allow),
        length_stat(length, allow.scalar["run.length"], dt_ns),
        *final_stats(finals, allow.scalar, max(length), dt_ns),
        *commands,
        task_stat(golden, candidate, allow.task, max(length), dt_ns),
        *count_stats(golden.events, candidate.events, allow.scalar, max(length), dt_ns),
        *pictures,
    ]
    matched, shifted, event_diffs = _events(golden, candidate, allow, event_kinds)
    first_annotation = _first_of(fields, "commands.annotations")
    # annotations alone are still a difference, but never ahead of a physical one
    first = _first(fields, event_diffs, dt_ns, allow.event_window) or first_annotation
    notes += allow.commands_note() + pictures_note + allow.events_note()
    notes += _decimation_notes(golden, candidate, int(gi.shape[0]))
    notes += identity_notes(identities, match=first is None, bit_identical=bit_identical(fields))
    return DiffResult(
        golden=run_summary(golden),
        candidate=run_summary(candidate),
        tolerances=tol,
        fields=fields,
        events_matched=matched,
        events_shifted=shifted,
        event_diffs=event_diffs,
        final_poses=finals,
        length=length,
        steps_compared=int(gi.shape[0]),
        config_differences=config_differences(
            {**golden.config.to_dict(), "run": golden.run or {}},
            {**candidate.config.to_dict(), "run": candidate.run or {}},
        ),
        notes=notes,
        first=first,
        first_command=_first_of(fields, "commands.sequence"),
        first_annotation=first_annotation,
        likely_cause=(
            "" if first is None
            else likely_cause(golden.commands, first, golden.config.profile.joint_names)
        ),
        events_compared=tol.event_window_steps is not None,
        floor=floor,
        identity=identities,
    )


def _require_frames(golden: Recording, candidate: Recording) -> None:
    g, c = golden.frames, candidate.frames
    if len(g) == 0 or len(c) == 0:
        raise RecordingError(
            f"cannot compare a run without frames (golden {golden.path or '<memory>'}: {len(g)} "
            f"frames, candidate {candidate.path or '<memory>'}: {len(c)} frames)"
        )


def _pictures(
    golden: Recording, candidate: Recording, allow: Allowances, dt_ns: int
) -> tuple[list[FieldStat], list[str]]:
    """The camera pictures' field (none when neither run has a camera), and the note when the
    tolerances leave them out."""
    if not (golden.config.cameras or candidate.config.cameras):
        return [], []
    stat = image_stat(golden, candidate, allow.scalar["images.pixels"], dt_ns)
    if not allow.images_off:
        return [stat], []
    return [stat], ["camera pictures are not compared under these tolerances (images.pixels = inf)"]


def _events(
    golden: Recording, candidate: Recording, allow: Allowances, kinds: frozenset[str] | None
) -> tuple[int, int, list[EventDiff]]:
    """(matched, shifted, differences) of the events paired within the allowed window, up to
    where the candidate's own events change with last-bit noise; nothing when not paired."""
    if allow.event_window is None:
        return 0, 0, []
    matched, shifted, diffs = match_events(golden.events, candidate.events, allow.event_window,
                                           kinds)
    if allow.events_until is not None:
        diffs = [d for d in diffs if d.step < allow.events_until]
    return matched, shifted, diffs


def _first_of(fields: list[FieldStat], name: str) -> Divergence | None:
    return next((f.first for f in fields if f.name == name), None)


def _decimation_notes(golden: Recording, candidate: Recording, compared: int) -> list[str]:
    notes = []
    for name, rec in (("golden", golden), ("candidate", candidate)):
        rate = rec.rate_steps
        if rate > 1:
            notes.append(
                f"the {name} is decimated (a frame every {rate} steps): frames compare "
                f"on the {compared} "
                "steps both files keep; commands, events and final poses compare at every step"
            )
    return notes


def _first(
    fields: list[FieldStat], event_diffs: list[EventDiff], dt_ns: int, window_steps: int | None
) -> Divergence | None:
    """The first physical divergence: of the fields (annotations aside) and the events."""
    candidates = [
        f.first for f in fields if f.first is not None and f.name != "commands.annotations"
    ]
    for d in event_diffs[:1]:
        element = f"{d.event_kind} {d.body}".strip()
        candidates.append(
            Divergence(
                step=d.step,
                t_s=d.step * dt_ns * 1e-9,
                channel="events",
                field=d.kind,
                element=element,
                expected=[d.expected_step],
                actual=[d.actual_step],
                difference=(
                    float(abs(d.expected_step - d.actual_step)) if d.kind == "moved" else INF
                ),
                tolerance=float(window_steps or 0),
                unit="steps",
            )
        )
    return min(candidates, key=lambda d: d.step) if candidates else None


def run_summary(rec: Recording) -> dict:
    f = rec.frames
    return {
        "path": rec.path,
        "profile": rec.config.profile.name,
        "run": rec.run,
        "frames": len(f),
        "first_step": int(f.step[0]) if len(f) else -1,
        "last_step": int(f.step[-1]) if len(f) else -1,
        "dt_ns": rec.config.dt_ns,
        "objects": [o.name for o in rec.config.objects],
        "events": len(rec.events),
        "commands": len(rec.commands),
    }


def config_differences(g: dict, c: dict, prefix: str = "") -> list[tuple[str, str, str]]:
    """Leaf-by-leaf differences of two configuration dicts: (key, golden, candidate)."""
    out = []
    for key in sorted(set(g) | set(c)):
        name = f"{prefix}{key}"
        a, b = g.get(key, "<absent>"), c.get(key, "<absent>")
        if isinstance(a, dict) and isinstance(b, dict):
            out += config_differences(a, b, name + ".")
        elif _dict_list(a) and _dict_list(b) and len(a) == len(b):
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                out += config_differences(x, y, f"{name}[{i}].")
        elif _plain(a) != _plain(b):
            out.append((name, repr(_plain(a)), repr(_plain(b))))
    return out


def _dict_list(x) -> bool:
    return isinstance(x, list | tuple) and bool(x) and all(isinstance(v, dict) for v in x)


def _plain(x):
    return [_plain(v) for v in x] if isinstance(x, list | tuple) else x
