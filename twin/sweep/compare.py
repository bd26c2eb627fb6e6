"""`twin sweep compare A B`: two sweeps' results side by side. A and B are result folders (what
`twin sweep --out DIR` wrote: results.parquet and sweep.toml) or golden definitions NAME.toml
with NAME.results.parquet beside them. Their scenarios are the same ones when both have the same
seed and the same varied keys (scenario i's values depend only on the seed, i and the key), and
then they are compared scenario by scenario (paired.pair); otherwise as two independent samples
(unpaired.py). What else differs between the two definitions (robot, task parameters, a
distribution, the rate) is named: it is what the comparison measures."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from twin.model.errors import ConfigError
from twin.record.outputs import write_atomic
from twin.sweep import paired, unpaired
from twin.sweep.spec import TOLERANCES, SweepSpec, load_spec

RESULTS, DEFINITION = "results.parquet", "sweep.toml"


@dataclass
class Run:
    """One side of a comparison: its label, definition, the file that re-runs it and its results."""

    label: str
    spec: SweepSpec
    definition: str
    side: paired.Side


def load_run(path: str) -> Run:
    """A result folder or a golden definition, as a Run; ConfigError (exit 2) naming what is
    missing."""
    p = Path(path)
    if p.suffix == ".toml":
        results = p.with_name(p.stem + ".results.parquet")
        if not results.exists():
            raise ConfigError(f"{path!r} has no {results.name} beside it; expected a golden with "
                              f"its results (`twin check --update {path}` writes them) or a "
                              "result folder")
        definition = p
    elif p.is_dir():
        results, definition = p / RESULTS, p / DEFINITION
        for f in (results, definition):
            if not f.exists():
                raise ConfigError(f"{path!r} has no {f.name}; expected a folder `twin sweep --out` "
                                  "wrote")
    else:
        raise ConfigError(f"{path!r} is neither a result folder nor a sweep definition .toml; "
                          "expected what `twin sweep --out DIR` wrote")
    spec = load_spec(definition)
    return Run(path, spec, str(definition), paired.read_side(results, path))


def definition_differences(a: SweepSpec, b: SweepSpec) -> list[str]:
    """What differs between two definitions, besides the scenario count, one item each."""
    out = []
    for name in ("task", "robot", "seed", "rate_hz", "timeout_s"):
        va, vb = getattr(a, name), getattr(b, name)
        if name in ("task", "robot") and isinstance(va, str) and isinstance(vb, str):
            va, vb = _name(va), _name(vb)
        if va != vb:
            out.append(f"{name} {va} -> {vb}")
    for key in sorted(set(a.params) | set(b.params)):
        if a.params.get(key) != b.params.get(key):
            out.append(f"params.{key} {a.params.get(key)} -> {b.params.get(key)}")
    va, vb = dict(a.vary), dict(b.vary)
    for key in [k for k, _ in a.vary] + [k for k, _ in b.vary if k not in va]:
        if va.get(key) != vb.get(key):
            out.append(f"vary.{key} {va.get(key)} -> {vb.get(key)}")
    return out


def _name(text: str) -> str:
    return Path(text).name if text.endswith((".py", ".toml")) else text


@dataclass
class Comparison:
    reference: Run
    new: Run
    differences: list[str]
    result: paired.Paired | unpaired.Unpaired
    problems: list[str]  # what makes B worse than A (--fail-if-worse)
    warnings: list[str] = field(default_factory=list)  # said, failing nothing (paired.warnings)

    @property
    def is_paired(self) -> bool:
        return isinstance(self.result, paired.Paired)

    def as_dict(self) -> dict:
        return {**self.result.as_dict(), "definition_differences": self.differences,
                "worse": self.problems, "warnings": self.warnings}

    def text(self) -> str:
        head = ("definitions differ in: " + "; ".join(self.differences) + "\n"
                if self.differences else "definitions are the same\n")
        body = (paired.report_text(self.result, self.new.definition) if self.is_paired
                else unpaired.unpaired_text(self.result))
        verdict = ("worse: " + "; ".join(self.problems) if self.problems
                   else "not worse beyond sampling noise")
        warned = "".join(f"warning: {w}\n" for w in self.warnings)
        return head + body + warned + verdict + "\n"

    def markdown(self) -> str:
        body = (paired.report_markdown(self.result, self.new.definition) if self.is_paired
                else unpaired.unpaired_markdown(self.result))
        diffs = "\n".join(f"- {d}" for d in self.differences) or "- none"
        verdict = "\n".join(f"- {p}" for p in self.problems) or "- not worse beyond sampling noise"
        verdict += "".join(f"\n- warning: {w}" for w in self.warnings)
        return f"{body}\n## Definitions differ in\n\n{diffs}\n\n## Verdict\n\n{verdict}\n"


def compare(a: Run, b: Run) -> Comparison:
    """B (new) against A (reference): paired when the scenarios are the same ones."""
    diffs = definition_differences(a.spec, b.spec)
    keys_a, keys_b = sorted(a.side.keys), sorted(b.side.keys)
    why = None
    if a.spec.seed != b.spec.seed:
        why = f"seeds differ: {a.spec.seed} and {b.spec.seed}"
    elif keys_a != keys_b:
        why = f"varied keys differ: {', '.join(keys_a) or 'none'} and {', '.join(keys_b) or 'none'}"
    if why is None:
        # the same distributions give the same values: another value is a changed file
        same_vary = dict(a.spec.vary) == dict(b.spec.vary)
        moved = paired.first_moved(a.side, b.side) if same_vary else None
        if moved is not None:
            key, scenario = moved
            raise ConfigError(
                f"results {b.label!r} column {key!r}: scenario {scenario} has another value than "
                f"in {a.label!r}; expected the same varied values per scenario to pair them (the "
                "results were changed, or made by another version)"
            )
        result = paired.pair(a.side, b.side)
        if result.n == 0:
            raise ConfigError(f"{a.label!r} and {b.label!r} share no scenario numbers; expected "
                              "sweeps of the same scenarios (or another seed: an unpaired "
                              "comparison)")
        shift = {**TOLERANCES, **a.spec.tolerance}["placement_shift_mm"]
        problems = paired.problems(result, "significant", shift)
        warnings = paired.warnings(result, "significant", a.spec.tolerance.get("success_drop_pct"))
    else:
        result = unpaired.unpaired(a.side, b.side, why)
        problems, warnings = unpaired.unpaired_problems(result), []
    return Comparison(
        reference=a,
        new=b,
        differences=diffs,
        result=result,
        problems=problems,
        warnings=warnings,
    )


def write_report(comparison: Comparison, path: str) -> None:
    """--report FILE: Markdown (.md) or JSON (.json) by its extension."""
    if path.endswith(".json"):
        text = json.dumps(comparison.as_dict(), indent=2, allow_nan=False) + "\n"
    elif path.endswith(".md"):
        text = comparison.markdown()
    else:
        raise ConfigError(f"--report {path!r} is invalid; expected a file ending in .md or .json")
    write_atomic(path, text)
