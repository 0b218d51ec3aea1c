"""`Pacer`: a client's side of a lockstep paced by its client (`sim_world.sitl.rig.LockstepPace`).

A simulated autopilot in lockstep at speed `max` (PX4 or ArduPilot SITL behind their bridges) runs only
while its client waits on it: the client says so with each pace (`flight.sim_launcher.SimulatorProcess.
pace`: one line on the simulator's stdin), and the world runs a short lead past the last one. A client
waits on the vehicle in two ways: polling its clock (a sleep, a wait for a state, a move), where a pace
is due every `period_s` of the vehicle's clock (`tick`), and blocked in a command until the vehicle
answers (`blocked()`), where the vehicle's clock may not move at all until the world runs, so a helper
thread paces every `wall_period_s` of wall time. Without a pace function every method does nothing: a
real vehicle, or a simulator that is not paced.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager


class Pacer:
    """Paces a lockstepped simulator while its client waits on it (see the module docstring)."""

    def __init__(
        self, pace: Callable[[], None] | None, period_s: float = 0.05, wall_period_s: float = 0.02
    ) -> None:
        if not (period_s > 0 and wall_period_s > 0):
            raise ValueError("Pacer: period_s and wall_period_s must be > 0")
        self._pace, self.period_s, self.wall_period_s = pace, period_s, wall_period_s
        self._last_s = -math.inf

    def tick(self, vehicle_time_s: float) -> None:
        """A wait polled the vehicle's clock: pace if `period_s` of it passed since the last pace."""
        if self._pace is not None and vehicle_time_s - self._last_s >= self.period_s:
            self._last_s = vehicle_time_s
            self._pace()

    @contextmanager
    def blocked(self) -> Iterator[None]:
        """Pace every `wall_period_s` while the block waits for the vehicle (a command and its answer)."""
        if self._pace is None:
            yield
            return
        pace, done = self._pace, threading.Event()

        def keep_pacing() -> None:
            while not done.wait(self.wall_period_s):
                pace()

        pace()
        thread = threading.Thread(target=keep_pacing, name="vehicle-pacer", daemon=True)
        thread.start()
        try:
            yield
        finally:
            done.set()
            thread.join(1.0)
