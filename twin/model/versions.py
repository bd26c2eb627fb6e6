"""The physics engine's API version, which recordings name: filled in by the engine module when it is
loaded (sim/world.py), so the recorder reads it without importing the simulation. Every process that
records has built a Twin, and so loaded the engine, first."""

from __future__ import annotations

ENGINE: dict[str, str] = {}  # e.g. {"pybullet_api": "202010061"}
