"""The one interface every flight backend implements (PyBullet in-process, MAVSDK over MAVLink).

The contract follows PX4's offboard rules so that code written against the
simulation flies a real vehicle: a velocity setpoint must be set before
`start_offboard()`, offboard is left (`stop_offboard()`, which holds) before
`land()`, and every blocking call has a timeout and raises a typed
`flight.errors.FlightError` when it runs out. Frames: NED world, FRD body.

Time: each vehicle has its own clock (`time_s()`, `sleep()`): wall time for a
real link, simulated time for the in-process PyBullet backend, which advances
its physics only inside `sleep()` and the blocking calls. Code that waits on a
vehicle must use these, never `time.sleep`, so that it runs faster than real
time in simulation.
"""

from __future__ import annotations

import abc
import math
import time
from collections.abc import Callable
from types import TracebackType

from flight.errors import CommandDeniedError, FlightTimeoutError
from flight.types import Telemetry, VelocityBody

TAKEOFF_ATTEMPTS = 2
"""A MAVLink backend's takeoff whose vehicle disarmed on its own on the ground (PX4's COM_DISARM_PRFLT,
ArduCopter's DISARM_DELAY: 10 s after arming without a takeoff) is asked this often in all, the vehicle
armed again first, where the backend armed it."""


class Vehicle(abc.ABC):
    """A multicopter commanded with body-frame velocity setpoints in offboard mode."""

    #: True when the vehicle's clock is wall time (a real link); False for simulated time.
    realtime: bool = True
    #: True when telemetry arrives at wall-clock rates whatever the vehicle's clock (a MAVLink link to a
    #: simulator running faster than real time): then every timeout also waits its length in wall time.
    wall_paced_telemetry: bool = False

    @abc.abstractmethod
    def connect(self, timeout_s: float | None = None) -> None:
        """Open the link and wait until the autopilot is discovered."""

    @abc.abstractmethod
    def wait_ready(self, timeout_s: float | None = None) -> None:
        """Wait until the position estimate and home position are valid (needed for offboard)."""

    def prepare_takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:  # noqa: B027
        """Before arming: what the backend sets ahead of a takeoff to `altitude_m` (PX4 through MAVSDK: its
        takeoff altitude parameter); nothing by default."""

    @abc.abstractmethod
    def arm(self, timeout_s: float | None = None) -> None:
        """Arm, retrying while the autopilot says 'temporarily rejected', until armed shows in telemetry."""

    @abc.abstractmethod
    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        """Take off to `altitude_m` above home and return once in the air near that altitude."""

    @abc.abstractmethod
    def start_offboard(self, timeout_s: float | None = None) -> None:
        """Switch to offboard (a setpoint must have been set) and confirm it from telemetry."""

    @abc.abstractmethod
    def set_velocity_body(self, velocity: VelocityBody) -> None:
        """Set the body-frame velocity setpoint (sent once; the backend keeps the stream alive)."""

    @abc.abstractmethod
    def hold(self) -> None:
        """Stop moving: zero velocity in offboard, otherwise the autopilot's Hold mode."""

    @abc.abstractmethod
    def stop_offboard(self, timeout_s: float | None = None) -> None:
        """Leave offboard for Hold and confirm it from telemetry (do this before landing)."""

    @abc.abstractmethod
    def land(self, timeout_s: float | None = None) -> None:
        """Land and return once telemetry shows the vehicle on the ground."""

    @abc.abstractmethod
    def disarm(self, timeout_s: float | None = None) -> None:
        """Disarm; a vehicle that already disarmed itself after landing counts as success."""

    @abc.abstractmethod
    def telemetry(self) -> Telemetry:
        """The latest state. Raises `LinkLostError` when the vehicle has stopped answering."""

    @abc.abstractmethod
    def time_s(self) -> float:
        """The vehicle's clock in seconds (wall or simulated; only differences are meaningful)."""

    @abc.abstractmethod
    def sleep(self, seconds: float) -> None:
        """Let `seconds` pass on the vehicle's clock (steps the physics in simulation)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the link and every thread or resource the backend holds. Idempotent."""

    def kill(self, timeout_s: float | None = None) -> None:
        """Stop the motors now, in the air too (MAVLink's forced disarm, 21196): an operator's last resort,
        after which a flying vehicle falls. Returns once telemetry shows it disarmed. A backend that cannot
        raises `CommandDeniedError`."""
        raise CommandDeniedError("kill()", "UNSUPPORTED", f"{type(self).__name__} cannot stop its motors")

    def status_texts(self) -> list[str]:
        """Messages the autopilot sent (STATUSTEXT), oldest first; empty where there are none."""
        return []

    def send_land(self) -> bool:
        """Command LAND once, watching no telemetry: the last word to a vehicle whose link was lost (its
        uplink may still work). True when the vehicle acknowledged it; False when nothing says it landed
        or will. A backend without a link to lose lands as `land()` does."""
        self.land()
        return True

    def __enter__(self) -> Vehicle:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class Deadline:
    """When a wait on `vehicle` gives up: `timeout_s` after now on the vehicle's clock and, for a
    vehicle with `wall_paced_telemetry`, on the wall clock too. At ×k a mode change shown by PX4's
    1 Hz heartbeat may take a wall second, k simulated seconds: a timeout guards against a vehicle
    that does not answer, so it must not expire before the link could have answered."""

    def __init__(self, vehicle: Vehicle, timeout_s: float) -> None:
        self._vehicle = vehicle
        self.at_s = vehicle.time_s() + timeout_s
        self._wall_at_s = time.monotonic() + timeout_s if vehicle.wall_paced_telemetry else -math.inf

    def expired(self) -> bool:
        return self._vehicle.time_s() >= self.at_s and time.monotonic() >= self._wall_at_s

    def remaining_s(self) -> float:
        """Time left on the slower of the clocks it waits on (0 once expired)."""
        return max(0.0, self.at_s - self._vehicle.time_s(), self._wall_at_s - time.monotonic())


def wait_for(
    vehicle: Vehicle,
    predicate: Callable[[Telemetry], bool],
    timeout_s: float,
    origin: str,
    waiting_for: str,
    poll_s: float = 0.05,
) -> Telemetry:
    """Poll telemetry on the vehicle's clock until `predicate` holds, else raise `FlightTimeoutError`.

    `vehicle.telemetry()` raises on link loss, so no wait outlives a dead link.
    """
    deadline = Deadline(vehicle, timeout_s)
    while True:
        telemetry = vehicle.telemetry()
        if predicate(telemetry):
            return telemetry
        if deadline.expired():
            raise FlightTimeoutError(origin, timeout_s, waiting_for)
        vehicle.sleep(poll_s)
