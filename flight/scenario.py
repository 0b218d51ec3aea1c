"""The one-move flight (`dronectl move`, the flight benchmark, the backend tests), and opening a vehicle.

connect → ready → arm → take off → zero setpoint → offboard → one discrete move →
hold → leave offboard → land → disarm, inside `flight_guard` so that Ctrl-C or
any error ends in hold + land. The same function flies every backend, which is
what makes the PyBullet and MAVSDK results comparable.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

from drone_inspect_core.signing import SigningKey
from flight.moves import MoveResult, execute_move
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits, flight_guard
from flight.types import VelocityBody
from flight.vehicle import Vehicle

log = logging.getLogger(__name__)

MAX_MOVE_M = 5.0
"""The longest move along an axis: the default geofence's half-width (a longer one cannot be flown)."""

SIM_VEHICLE = "sim"
"""`--vehicle sim`: the in-process PyBullet backend (no MAVLink)."""


@dataclass(frozen=True)
class MoveFlight:
    """One discrete move: `right_m` / `forward_m` / `down_m` at `speed_m_s`, from `takeoff_alt_m`."""

    right_m: float = 0.5
    forward_m: float = 0.0
    down_m: float = 0.0
    speed_m_s: float = 0.25
    takeoff_alt_m: float = 2.5
    settle_speed_m_s: float = 0.1
    settle_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        for name in ("right_m", "forward_m", "down_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and abs(value) <= MAX_MOVE_M):
                raise ValueError(
                    f"MoveFlight.{name} must be a distance within ±{MAX_MOVE_M:g} m, got {value}"
                )
        if not self.speed_m_s > 0:
            raise ValueError(f"MoveFlight.speed_m_s must be > 0, got {self.speed_m_s}")
        if not self.takeoff_alt_m > 0:
            raise ValueError(f"MoveFlight.takeoff_alt_m must be > 0, got {self.takeoff_alt_m}")
        if self.distance_m == 0:
            raise ValueError("MoveFlight: the move is empty (right_m, forward_m and down_m are all 0)")

    @property
    def distance_m(self) -> float:
        return (self.right_m**2 + self.forward_m**2 + self.down_m**2) ** 0.5

    @property
    def duration_s(self) -> float:
        return self.distance_m / self.speed_m_s

    @property
    def velocity(self) -> VelocityBody:
        scale = self.speed_m_s / self.distance_m
        return VelocityBody(self.forward_m * scale, self.right_m * scale, self.down_m * scale)


@dataclass(frozen=True)
class FlightTimings:
    """Wall-clock milestones of one flight, in seconds from `t0` (the call's start unless given)."""

    connected_s: float
    ready_s: float
    armed_s: float
    airborne_s: float
    offboard_active_s: float
    move_done_s: float
    landed_s: float

    @property
    def connected_to_offboard_s(self) -> float:
        return self.offboard_active_s - self.connected_s


@dataclass(frozen=True)
class MoveFlightResult:
    move: MoveResult
    timings: FlightTimings
    status_texts: list[str] = field(default_factory=list)


def fly_move(
    vehicle: Vehicle, flight: MoveFlight, limits: SafetyLimits | None = None, t0: float | None = None
) -> MoveFlightResult:
    """Fly `flight` on `vehicle` (wrapped in `SafeVehicle(limits)`) from the ground back to the ground.

    `t0` is a `time.perf_counter()` value the milestones are measured from.
    """
    t0 = time.perf_counter() if t0 is None else t0
    marks: list[float] = []

    def mark() -> None:
        marks.append(time.perf_counter() - t0)

    safe = SafeVehicle(vehicle, limits)
    safe.connect()
    mark()
    with flight_guard(safe):
        safe.wait_ready()
        mark()
        safe.arm()
        mark()
        safe.takeoff(flight.takeoff_alt_m)
        mark()
        safe.set_velocity_body(VelocityBody())  # PX4 needs a setpoint before offboard
        safe.start_offboard()
        mark()
        log.info("offboard active; moving %s for %.2f s", flight.velocity, flight.duration_s)
        move = execute_move(
            safe, flight.velocity, flight.duration_s, flight.settle_speed_m_s, flight.settle_timeout_s
        )
        mark()
        safe.stop_offboard()
        safe.land()
        safe.disarm()
        mark()
    return MoveFlightResult(move, FlightTimings(*marks), safe.status_texts())


def open_vehicle(spec: str, seed: int = 0, signing_key: SigningKey | None = None) -> Vehicle:
    """`sim` → an in-process `PyBulletVehicle` (seeded); anything else is a MAVLink connection URL, flown
    with MAVSDK (PX4) or in GUIDED mode (ArduPilot) as its heartbeat says (`flight.autopilots`), behind a
    relay where it is `udpin://` (which signs the link with `signing_key`: `flight.relay.relay_in_front`).

    Imports each backend only when asked, so that a real-vehicle run never loads PyBullet.
    """
    if spec == SIM_VEHICLE:
        if signing_key is not None:
            raise ValueError("a signing key is for a MAVLink vehicle, not the in-process simulation")
        from flight.pybullet_backend import PyBulletVehicle

        return PyBulletVehicle.create(seed=seed)
    from flight.autopilots import MavlinkVehicle
    from flight.relay import relay_in_front

    relay, url = relay_in_front(spec, signing_key=signing_key)
    try:
        return MavlinkVehicle(url, shown_url=spec, link=relay)
    except BaseException:
        if relay is not None:
            relay.close()
        raise
