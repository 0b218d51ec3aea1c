"""Stopping a running flight operation from another thread: the operator's Hold, Land and Kill.

A flight session (`controller.missions.session`) runs one operation at a time (take off, centre an
instruction, land) in the thread that called it; an operator's interrupt comes from another thread
(a console's button). The operation sees its vehicle through `StoppableVehicle`: before every command
that could move the vehicle and in every wait, it checks whether a stop was asked for and then raises
`OperatorStop`, so the operation ends at its next step, move or poll instead of finishing it.

Waits are cut into slices of at most `STOP_POLL_S` on the vehicle's clock, so a stop is seen within
one slice (a move or a settle never runs out first). On a vehicle with a simulated clock nothing moves
between two of its calls (the physics steps only inside `sleep`), so a stop seen before the next slice
costs no simulated time at all; such a vehicle is only ever touched from the operation's thread.
On a real-time vehicle (MAVLink) the interrupt also commands the vehicle at once from its own thread;
`command_lock` then orders the operation's velocity commands against it, so no move command can land
after the interrupt's hold.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

from flight.types import Telemetry, VelocityBody
from flight.vehicle import Vehicle

STOP_POLL_S = 0.05
"""The longest slice of a wait between two looks at the stop events (vehicle clock)."""


class OperatorStop(BaseException):
    """The operator stopped the running operation (Hold, Land or Kill).

    A `BaseException` on purpose, like `KeyboardInterrupt`: no `except Exception` in the loop or the
    moves may swallow it, and `flight.safety.flight_guard` (which would land the vehicle) lets it pass;
    the session that asked for the stop decides what the vehicle does next."""


class StoppableVehicle(Vehicle):
    """`inner` as a running operation sees it: every moving command and every wait first checks `stops`
    (see the module docstring); everything else passes through."""

    def __init__(
        self, inner: Vehicle, stops: Sequence[threading.Event], command_lock: threading.RLock
    ) -> None:
        self.inner = inner
        self.stops = tuple(stops)
        self.command_lock = command_lock
        self.realtime = inner.realtime
        self.wall_paced_telemetry = inner.wall_paced_telemetry

    @property
    def stopped(self) -> bool:
        return any(stop.is_set() for stop in self.stops)

    def check(self) -> None:
        """Raise `OperatorStop` if a stop was asked for."""
        if self.stopped:
            raise OperatorStop("stopped by the operator")

    # --- checked: what moves the vehicle, and the waits -----------------------------------------
    def set_velocity_body(self, velocity: VelocityBody) -> None:
        with self.command_lock:  # the check and the command as one, against an interrupt's hold
            self.check()
            self.inner.set_velocity_body(velocity)

    def sleep(self, seconds: float) -> None:
        end_s = self.inner.time_s() + seconds
        while True:
            self.check()
            left_s = end_s - self.inner.time_s()
            if left_s <= 1e-9:
                return
            self.inner.sleep(min(STOP_POLL_S, left_s))

    def prepare_takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self.check()
        self.inner.prepare_takeoff(altitude_m, timeout_s)

    def arm(self, timeout_s: float | None = None) -> None:
        self.check()
        self.inner.arm(timeout_s)

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self.check()
        self.inner.takeoff(altitude_m, timeout_s)

    def start_offboard(self, timeout_s: float | None = None) -> None:
        with self.command_lock:
            self.check()
            self.inner.start_offboard(timeout_s)

    # --- passed through -----------------------------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        self.inner.connect(timeout_s)

    def wait_ready(self, timeout_s: float | None = None) -> None:
        self.inner.wait_ready(timeout_s)

    def hold(self) -> None:
        with self.command_lock:
            self.inner.hold()

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self.inner.stop_offboard(timeout_s)

    def land(self, timeout_s: float | None = None) -> None:
        self.inner.land(timeout_s)

    def disarm(self, timeout_s: float | None = None) -> None:
        self.inner.disarm(timeout_s)

    def kill(self, timeout_s: float | None = None) -> None:
        self.inner.kill(timeout_s)

    def telemetry(self) -> Telemetry:
        return self.inner.telemetry()

    def time_s(self) -> float:
        return self.inner.time_s()

    def status_texts(self) -> list[str]:
        return self.inner.status_texts()

    def send_land(self) -> bool:
        return self.inner.send_land()

    def close(self) -> None:
        """The session closes the vehicle it wraps; an operation never does."""
