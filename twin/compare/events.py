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
                diffs.append(_event_diff("moved", key, ge, ce))
            else:
                matched += 1
                shifted += shift > 0
        diffs += [_event_diff("missing", key, e, None) for e in gs[len(cs) :]]
        diffs += [_event_diff("extra", key, None, e) for e in cs[len(gs) :]]
    diffs.sort(key=lambda d: (d.step, d.kind, d.event_kind, d.body))
    return matched, shifted, diffs


def _event_diff(
    kind: str, key: tuple[str, str], golden: Event | None, candidate: Event | None
) -> EventDiff:
    """A difference of the events of key (kind, body); its message is the golden's when it has
    one."""
    return EventDiff(
        kind=kind,
        event_kind=key[0],
        body=key[1],
        expected_step=golden.step if golden is not None else None,
        actual_step=candidate.step if candidate is not None else None,
        message=(golden if golden is not None else candidate).message,
    )
