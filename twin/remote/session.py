"""The scene a remote server exposes: stopped, running or paused, one Twin and one recording per
run.

As in CoppeliaSim, the scene waits stopped until a client starts the simulation; stopping ends the
run, finalizes its recording and resets the scene (a fresh Twin). Calls made while stopped act on
the fresh twin at step 0 and belong to the next run's recording.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, OutputError, TwinError
from twin.model.images import CameraImage
from twin.model.sink import Sink
from twin.model.types import Command, Event, Frame
from twin.sim.twin import Twin
from twin.sim.world import engine_versions

SIMULATION_STOPPED = 0x00
SIMULATION_PAUSED = 0x08
SIMULATION_ADVANCING_RUNNING = 0x11
# Commands a stopped scene holds for its next run (each is kept, then recorded): a client looping
# sim.setJointPosition while stopped would otherwise grow the server without bound.
MAX_PENDING_COMMANDS = 10_000


class _Relay(Sink):
    """The twin's one sink: holds what happens while stopped, forwards it to the recorders once the
    run starts (so Commands given before startSimulation are in the run's recording). Past
    MAX_PENDING_COMMANDS held Commands it refuses the next one before the twin applies it."""

    def __init__(self) -> None:
        self.pending: list[tuple[str, Any]] = []
        self.pending_commands = 0
        self.targets: list = []
        self.holding = True

    def _pass(self, method: str, item: Any) -> None:
        """Hold item while stopped; hand it to the recorders attached (none while stopped)."""
        if self.holding:
            self.pending.append((method, item))
        for s in self.targets:
            getattr(s, method)(item)

    def on_frame(self, frame: Frame) -> None:
        self._pass("on_frame", frame)

    def on_command(self, command: Command) -> None:
        if self.holding:
            if self.pending_commands >= MAX_PENDING_COMMANDS:  # raised before the twin applies it
                raise ConfigError(
                    f"the simulation is stopped and already holds {MAX_PENDING_COMMANDS} commands "
                    "for its next run; start it (sim.startSimulation) or stop sending"
                )
            self.pending_commands += 1
        self._pass("on_command", command)

    def on_event(self, event: Event) -> None:
        self._pass("on_event", event)

    def on_image(self, image: CameraImage) -> None:
        self._pass("on_image", image)

    def attach(self, sinks: list) -> None:
        for method, item in self.pending:
            for s in sinks:
                getattr(s, method)(item)
        self.pending.clear()
        self.pending_commands = 0
        self.holding = False
        self.targets = list(sinks)


def run_path(base: Path, run_index: int) -> Path:
    """NAME.ext for the first run, then NAME-2.ext, NAME-3.ext, ..."""
    return base if run_index == 1 else base.with_name(f"{base.stem}-{run_index}{base.suffix}")


class Scene:
    """A Twin behind CoppeliaSim's simulation states, recording each start..stop run to its own
    file."""

    def __init__(
        self,
        config: TwinConfig,
        *,
        mcap_path: str | None = None,
        rrd_path: str | None = None,
        rate: int = 1,
        mode: str = "realtime",
        log: Callable[[str], None] = print,
    ) -> None:
        self.config = config
        self.mcap_path = Path(mcap_path) if mcap_path else None
        self.rrd_path = Path(rrd_path) if rrd_path else None
        self.rate = rate
        self.mode = mode
        self.log = log
        self.state = SIMULATION_STOPPED
        self.run_index = 0  # runs started so far
        self._recorders: contextlib.ExitStack | None = None
        self._files: list[str] = []
        self.twin = self._fresh_twin()

    def _fresh_twin(self) -> Twin:
        self.relay = _Relay()
        return Twin(self.config, sinks=[self.relay])

    @property
    def running(self) -> bool:
        return self.state == SIMULATION_ADVANCING_RUNNING

    def start(self) -> None:
        if self.state == SIMULATION_PAUSED:
            self.state = SIMULATION_ADVANCING_RUNNING
            self.log(f"simulation resumed at t={self.twin.t_s:.3f} s")
            return
        if self.state != SIMULATION_STOPPED:
            return
        self.run_index += 1
        sinks: list = []
        self._files = []
        if self.mcap_path or self.rrd_path:
            sinks = self._open_recorders()
        self.relay.attach(sinks)
        self.state = SIMULATION_ADVANCING_RUNNING
        where = f", recording to {', '.join(self._files)}" if self._files else ""
        self.log(
            f"simulation started: run {self.run_index}, robot "
            f"{self.config.profile.name}, {self.mode}{where}"
        )

    def _open_recorders(self) -> list:
        try:
            from twin.record import open_recorders
        except ImportError as err:
            raise ConfigError(f"recording is unavailable in this installation: {err}") from err
        mcap = str(run_path(self.mcap_path, self.run_index)) if self.mcap_path else None
        rrd = str(run_path(self.rrd_path, self.run_index)) if self.rrd_path else None
        for path in (mcap, rrd):
            if path:
                Path(path).parent.mkdir(parents=True, exist_ok=True)
        run = {
            "source": "remote",
            "task": "",
            "params": {"robot": self.config.profile.name, "mode": self.mode, "run": self.run_index},
        }
        stack = contextlib.ExitStack()
        try:
            sinks = stack.enter_context(
                open_recorders(
                    self.config,
                    run,
                    mcap_path=mcap,
                    rrd_path=rrd,
                    rate=self.rate,
                    engine=engine_versions(),
                )
            )
        except BaseException:
            stack.close()
            self.run_index -= 1
            raise
        self._recorders = stack
        self._files = [p for p in (mcap, rrd) if p]
        return list(sinks)

    def pause(self) -> None:
        if self.state == SIMULATION_ADVANCING_RUNNING:
            self.state = SIMULATION_PAUSED
            self.log(f"simulation paused at t={self.twin.t_s:.3f} s")

    def stop(self, *, reset: bool = True) -> None:
        """End the run: finalize its recording, then reset the scene (which releases what the pad
        held); reset=False at shutdown, where no next run needs a fresh twin.

        The recording ends with the run's last step as simulated; the release is the reset's doing,
        not an event of the run, so `twin replay` (which feeds the Commands back) reproduces the
        file exactly.
        """
        if self.state == SIMULATION_STOPPED:
            return
        twin = self.twin
        steps, t_s = twin.step_index, twin.t_s
        held = twin.frame.held_body
        self.state = SIMULATION_STOPPED
        try:
            twin.finish_pictures()  # the run's last camera pictures, before its recording closes
            self._close_recorders()
        finally:
            self.relay.targets = []
            if reset:
                twin.close()
                self.twin = self._fresh_twin()
        where = f"; recorded {', '.join(self._files)}" if self._files else ""
        holding = f", released {twin.config.objects[held].name}" if held >= 0 else ""
        self.log(
            f"simulation stopped: run {self.run_index} lasted {steps} steps ({t_s:.3f} "
            f"s){holding}{where}"
        )

    def _close_recorders(self) -> None:
        stack, self._recorders = self._recorders, None
        if stack is not None:
            try:
                stack.close()
            except TwinError:
                raise
            except Exception as err:
                raise OutputError(f"could not finalize the recording {self._files}: {err}") from err

    def advance(self, n: int) -> None:
        """Step the twin n physics steps if the simulation is running."""
        if n > 0 and self.state == SIMULATION_ADVANCING_RUNNING:
            self.twin.step(n)

    def close(self) -> None:
        """Server shutdown: end a running run cleanly, then release the twin."""
        try:
            self.stop(reset=False)
        finally:
            self.twin.close()
