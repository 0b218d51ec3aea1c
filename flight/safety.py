"""Safety rules that hold whatever the backend: speed limits, a geofence box, timeouts, a safe stop.

The limits are applied by `flight.safe_vehicle.SafeVehicle` to every command
before it reaches a backend (a command above a limit is clipped, never sent as
is). `flight_guard(vehicle)` wraps a flight so that Ctrl-C or any exception
inside it ends with the vehicle holding, then landing.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from drone_inspect_core.frames import heading_to_world_ned, world_ned_to_heading
from flight.errors import FlightError, LinkLostError
from flight.types import PositionNed, Telemetry, VelocityBody
from flight.vehicle import Vehicle

log = logging.getLogger(__name__)


def _check_positive(owner: object, *names: str) -> None:
    for name in names:
        value = getattr(owner, name)
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{type(owner).__name__}.{name} must be a positive number, got {value!r}")


@dataclass(frozen=True)
class FlightTimeouts:
    """A timeout for every wait on a vehicle, in seconds of the vehicle's clock."""

    connect_s: float = 15.0
    ready_s: float = 60.0  # PX4 SITL with SIH: estimator ready 31-35 s after boot
    arm_s: float = 15.0
    takeoff_s: float = 30.0
    mode_change_s: float = 5.0
    land_s: float = 45.0
    disarm_s: float = 10.0

    def __post_init__(self) -> None:
        _check_positive(
            self, "connect_s", "ready_s", "arm_s", "takeoff_s", "mode_change_s", "land_s", "disarm_s"
        )


@dataclass(frozen=True)
class GeofenceBox:
    """A box around the start point (where the vehicle armed): half-widths north/east, a height band.

    Commands that would carry the vehicle out within `lookahead_s` lose their
    outward component; a vehicle found more than `breach_margin_m` outside (drift,
    wind) raises `GeofenceBreachError`, which `flight_guard` turns into hold + land.
    """

    half_width_north_m: float = 5.0
    half_width_east_m: float = 5.0
    max_up_m: float = 5.0
    max_down_m: float = 0.5
    lookahead_s: float = 0.5
    breach_margin_m: float = 0.5

    def __post_init__(self) -> None:
        _check_positive(self, "half_width_north_m", "half_width_east_m", "max_up_m", "lookahead_s")
        if not (self.max_down_m >= 0.0 and self.breach_margin_m >= 0.0):
            raise ValueError("GeofenceBox.max_down_m and breach_margin_m must be >= 0")

    def bounds(
        self, origin: PositionNed
    ) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        """(low, high) for north, east and down around `origin`."""
        return (
            (origin.north_m - self.half_width_north_m, origin.north_m + self.half_width_north_m),
            (origin.east_m - self.half_width_east_m, origin.east_m + self.half_width_east_m),
            (origin.down_m - self.max_up_m, origin.down_m + self.max_down_m),
        )

    def excess_m(self, position: PositionNed, origin: PositionNed) -> float:
        """How far `position` lies outside the box (0 inside)."""
        excess = 0.0
        for value, (low, high) in zip(
            (position.north_m, position.east_m, position.down_m), self.bounds(origin), strict=True
        ):
            excess = max(excess, low - value, value - high)
        return excess


@dataclass(frozen=True)
class SafetyLimits:
    """Speed and yaw-rate limits, an optional geofence, the setpoint watchdog and the wait timeouts."""

    max_horizontal_speed_m_s: float = 1.0
    max_vertical_speed_m_s: float = 0.5
    max_yaw_rate_deg_s: float = 30.0
    geofence: GeofenceBox | None = field(default_factory=GeofenceBox)
    setpoint_timeout_s: float = 1.0
    timeouts: FlightTimeouts = field(default_factory=FlightTimeouts)

    def __post_init__(self) -> None:
        _check_positive(
            self,
            "max_horizontal_speed_m_s",
            "max_vertical_speed_m_s",
            "max_yaw_rate_deg_s",
            "setpoint_timeout_s",
        )


def clip_speed(velocity: VelocityBody, limits: SafetyLimits) -> VelocityBody:
    """Scale the horizontal part down to the limit (keeping its direction); clip vertical and yaw rates."""
    scale = 1.0
    if velocity.horizontal_m_s > limits.max_horizontal_speed_m_s:
        scale = limits.max_horizontal_speed_m_s / velocity.horizontal_m_s
    vmax, ymax = limits.max_vertical_speed_m_s, limits.max_yaw_rate_deg_s
    return VelocityBody(
        forward_m_s=velocity.forward_m_s * scale,
        right_m_s=velocity.right_m_s * scale,
        down_m_s=min(max(velocity.down_m_s, -vmax), vmax),
        yawspeed_deg_s=min(max(velocity.yawspeed_deg_s, -ymax), ymax),
    )


def clip_geofence(
    velocity: VelocityBody, telemetry: Telemetry, origin: PositionNed, fence: GeofenceBox
) -> VelocityBody:
    """Drop each NED component of `velocity` that would leave the box within the lookahead."""
    yaw_rad = math.radians(telemetry.attitude.yaw_deg)
    north, east = heading_to_world_ned(velocity.forward_m_s, velocity.right_m_s, yaw_rad)
    components = [north, east, velocity.down_m_s]
    clipped = False
    position = telemetry.position_ned
    for axis, (value, (low, high)) in enumerate(
        zip((position.north_m, position.east_m, position.down_m), fence.bounds(origin), strict=True)
    ):
        predicted = value + components[axis] * fence.lookahead_s
        if (predicted > high and components[axis] > 0.0) or (predicted < low and components[axis] < 0.0):
            components[axis] = 0.0
            clipped = True
    if not clipped:
        return velocity  # unchanged (not re-rotated: a round trip through the heading is not exact)
    forward, right = world_ned_to_heading(components[0], components[1], yaw_rad)
    return VelocityBody(forward, right, components[2], velocity.yawspeed_deg_s)


LAST_LAND_SENT = "the link was lost: a last LAND was sent and acknowledged; its landing could not be watched"
LAST_LAND_UNCONFIRMED = (
    "the link was lost: a last LAND was sent but could not be confirmed; the vehicle's own failsafe "
    "must bring it down"
)


def safe_stop(vehicle: Vehicle) -> str:
    """Best effort: hold, leave offboard, land if in the air, disarm; failures are logged, not raised.
    A vehicle that is on the ground and disarmed already gets nothing.

    A vehicle that no longer answers still gets one LAND (`Vehicle.send_land`: telemetry may be gone
    while commands still get through), and nothing else; the return value says what came of it ("" when
    the vehicle answered).
    """
    try:
        now = vehicle.telemetry()
    except LinkLostError as exc:
        log.error("safe stop: the vehicle is not answering (%s); sending a last LAND", exc)
        try:
            acknowledged = vehicle.send_land()
        except FlightError as land_error:
            log.error("safe stop: the last LAND could not be sent: %s", land_error)
            acknowledged = False
        said = LAST_LAND_SENT if acknowledged else LAST_LAND_UNCONFIRMED
        log.error("safe stop: %s", said)
        return said
    for name, step in (("hold", vehicle.hold), ("stop offboard", vehicle.stop_offboard)):
        if name != "hold":
            try:
                now = vehicle.telemetry()
            except FlightError:
                break  # said below, where the landing needs it
        if not now.armed and not now.in_air:
            # Down and disarmed already (its own failsafe landed it, say, after our uplink died): a hold
            # or a mode change would change nothing, and on a dead uplink each waits out its retries (6 s).
            log.warning("safe stop: the vehicle is on the ground and disarmed: nothing more to stop")
            return ""
        try:
            step()
        except FlightError as exc:
            log.warning("safe stop: %s failed: %s", name, exc)
    try:
        now = vehicle.telemetry()
    except LinkLostError:  # lost while holding: the last word is a LAND
        return safe_stop(vehicle)
    except FlightError as exc:
        log.error("safe stop: no telemetry (%s); cannot land the vehicle from here", exc)
        return ""
    for name, step in (("land", vehicle.land), ("disarm", vehicle.disarm)):
        if (name == "land" and not now.in_air) or (name == "disarm" and not now.armed and not now.in_air):
            continue
        try:
            step()
        except LinkLostError as exc:  # lost on the way down: the last word is still a LAND
            log.error("safe stop: %s: the link was lost (%s)", name, exc)
            return safe_stop(vehicle) if name == "land" else ""
        except FlightError as exc:
            log.error("safe stop: %s failed: %s", name, exc)
            return ""
    return ""


@contextmanager
def flight_guard(vehicle: Vehicle) -> Iterator[Vehicle]:
    """Run a flight; on Ctrl-C or any exception, `safe_stop` the vehicle and re-raise (a flight error
    then also says what came of a last LAND sent after a lost link)."""
    try:
        yield vehicle
    except (Exception, KeyboardInterrupt) as exc:
        log.error("flight interrupted (%s: %s): holding, then landing", type(exc).__name__, exc)
        aftermath = safe_stop(vehicle)
        if aftermath and isinstance(exc, FlightError):
            exc.add_aftermath(aftermath)
        raise
