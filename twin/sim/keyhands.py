"""What a key map's actions may do to the twin: the same handlers its Commands run."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from twin.sim.twin import Twin


class KeyHands:
    """What a key map's actions may do to the twin (model.keymaps.KeyPlayer plays them on it): the
    same handlers its Commands run, inside the `key` Command that holds them."""

    def __init__(self, twin: Twin) -> None:
        self._twin = twin

    def joint(self, name: str | int) -> int:
        return self._twin._joint(name)

    def target(self, joint: int) -> float:
        return self._twin._targets[joint]

    def limits(self, joint: int) -> tuple[float, float]:
        return self._twin._limits[joint]

    def drive(self, joint: int, q: float) -> None:
        self._twin._do_joint_target({"joint": joint, "q": q})

    def place(self, joint: int, q: float) -> None:
        self._twin._do_joint_position({"joint": joint, "q": q})

    def signal(self, name: str, value) -> None:
        self._twin._do_signal({"name": name, "value": value})
