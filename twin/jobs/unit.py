"""The unit of work that `twin.jobs` fans out: items are whole numbers (a sweep's scenarios, the
goldens of a check, a search round's points), and the unit says how to run one."""

from __future__ import annotations

from typing import Any, Protocol


class Unit(Protocol):
    """What a job layer needs of the work it runs; pickled to Dask workers, forked into children.

    - `warm()`: once in the process that forks the children (so each starts ready), never per item.
    - `run(item)`: the item's result, in a child. A `TwinError` (a file that cannot be written)
      stops the whole job with that error; any other exception is the item's failure.
    - `confirm(item)`: run an item again, alone, after its first run killed its process or hung.
    - `failed(item, reason, wall_s)`: the result of an item that gave none (its process died twice,
      or it ran past the time limit), saying why.
    """

    def warm(self) -> None: ...

    def run(self, item: int) -> Any: ...

    def confirm(self, item: int) -> Any: ...

    def failed(self, item: int, reason: str, wall_s: float) -> Any: ...
