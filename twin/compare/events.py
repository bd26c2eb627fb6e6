"""Matching events of two runs: by kind and body, in order, within a window of steps."""

from __future__ import annotations

from dataclasses import dataclass

from twin.model.types import Event


@dataclass
class EventDiff:
    # "missing" (in golden only), "extra" (in candidate only), "moved" (outside the window)
    kind: str
    event_kind: str
    body: str
    expected_step: int | None
    actual_step: int | None
    message: str = ""

    @property
    def step(self) -> int:
        return min(s for s in (self.expected_step, self.actual_step) if s is not None)


def by_key(
    events: list[Event], kinds: frozenset[str] | None = None
) -> dict[tuple[str, str], list[Event]]:
    """Events grouped by (kind, body), each group in order; only `kinds` when given."""
    out: dict[tuple[str, str], list[Event]] = {}
    for e in events:
        if kinds is None or e.kind in kinds:
            out.setdefault((e.kind, e.body), []).append(e)
    return out


def match_events(
    golden: list[Event],
    candidate: list[Event],
    window_steps: int,
    kinds: frozenset[str] | None = None,
) -> tuple[int, int, list[EventDiff]]:
    """Pair events by (kind, body) in order: the i-th golden with the i-th candidate of that key.

    Returns (matched, shifted within the window, [missing / extra / moved beyond the window]).
    """
    gk, ck = by_key(golden, kinds), by_key(candidate, kinds)
    matched = shifted = 0
    diffs: list[EventDiff] = []
    for key in sorted(set(gk) | set(ck)):
        gs, cs = gk.get(key, []), ck.get(key, [])
        for ge, ce in zip(gs, cs, strict=False):
            shift = abs(ge.step - ce.step)
            if shift > window_steps:
                diffs.append(EventDiff("moved", key[0], key[1], ge.step, ce.step, ge.message))
            else:
                matched += 1
                shifted += shift > 0
        diffs += [
            EventDiff("missing", key[0], key[1], e.step, None, e.message) for e in gs[len(cs) :]
        ]
        diffs += [
            EventDiff("extra", key[0], key[1], None, e.step, e.message) for e in cs[len(gs) :]
        ]
    diffs.sort(key=lambda d: (d.step, d.kind, d.event_kind, d.body))
    return matched, shifted, diffs
