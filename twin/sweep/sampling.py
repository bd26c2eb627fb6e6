"""Which values each scenario gets. A sampler maps a scenario index to {Key: value}; the runner asks
only that, so a search (the smallest perturbation that breaks a task) can later take the place of
random sampling without touching the workers, executors or results.

`RandomSampler` draws each key's value from a generator made for (seed, scenario, key) alone, never
a shared one: a scenario's values do not depend on the executor, the job count, the batch, the
order scenarios finish in, or on which other keys the sweep varies.
"""

from __future__ import annotations

import hashlib
from typing import Protocol

import numpy as np

from twin.sweep.dists import Dist
from twin.sweep.keys import Key


class Sampler(Protocol):
    def values(self, scenario: int) -> dict[Key, object]:
        """The varied values of one scenario (the same on every call and in every process)."""


class RandomSampler:
    """numpy's default_rng([seed, scenario, key id]) per key and scenario."""

    def __init__(self, seed: int, keys: tuple[tuple[Key, Dist], ...]) -> None:
        self.seed = seed
        self.keys = keys
        self._ids = tuple(_key_id(key.name) for key, _ in keys)

    def values(self, scenario: int) -> dict[Key, object]:
        return {key: dist.sample(np.random.default_rng([self.seed, scenario, key_id]))
                for (key, dist), key_id in zip(self.keys, self._ids, strict=True)}


def _key_id(name: str) -> int:
    """A stable number for a key's name (Python's hash() differs between processes)."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little")
