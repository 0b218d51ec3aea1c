"""The MAVSDK backend's link: its configuration, resending lost commands, and the telemetry cache.

`TelemetryCache` subscribes to MAVSDK's telemetry streams and keeps their latest values
under a lock. MAVSDK's sync callbacks all run on one MAVSDK thread, and blocking calls
return through it: the callbacks here only store values (and tell the link monitor the
vehicle was heard). `flight.mavsdk.vehicle.MavsdkVehicle` reads the cache.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from mavsdk import log_subscribe
from mavsdk.logging import LogLevel
from mavsdk.plugins.action import ActionError
from mavsdk.plugins.offboard import OffboardError
from mavsdk.plugins.telemetry import Telemetry as MavsdkTelemetry

from drone_inspect_core.state_streams import LANDED_STATE_HZ
from flight.link import LinkMonitor
from flight.safety import FlightTimeouts
from flight.status_texts import StatusTexts
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityNed
from flight.urls import validate_connection_url

log = logging.getLogger(__name__)

_NAN3 = (math.nan, math.nan, math.nan)
WALL_LINK_TIMEOUT_S = 2.0
"""A vehicle on the wall clock (a real one, a sim-vehicle at real time) is lost after this much silence."""
LOCKSTEP_LINK_TIMEOUT_S = 6.0
"""A simulated autopilot on its own clock (`clock="vehicle"`: PX4 SITL in lockstep, a sim-vehicle off real
time) is lost after this much silence (wall time): on a busy machine it is starved for seconds at a time
(px4-sitl collections and sim-mavlink benchmark missions ended LINK_LOST after 2.0-2.8 s of silence at
load 24-34), while one that died is still noticed within seconds."""


PX4_PARAMETER_SAVE_GUARD_S = 2.5
"""PX4 saves its parameters 0.3 s after a change, and at most once every 2 s (`param_autosave`), and it
changes some itself when it arms (the flight's UUID) and disarms (the flight-time totals). A parameter
set while a save ran failed the save's verify ("invalid BSON value"), and PX4 in lockstep then stalled
for good (its simulator link silent: LINK_LOST): the next mission's takeoff altitude, set soon after the
last mission's disarm on a warm PX4, stalled it in 2 of 3 runs of `dronectl benchmark-missions --n 2
--seed 11 --vehicle px4-sitl --planner latent,classic,random,oracle` (8 missions each). 2.5 s after an
arming change the save it caused is over, and the save of the new altitude comes 0.3 s after it is set
(`PARAMETER_SAVE_S` waits that out)."""


@dataclass(frozen=True)
class MavsdkConfig:
    """How to reach the vehicle and how long to wait for it."""

    url: str = "udpin://0.0.0.0:14540"
    timeouts: FlightTimeouts = field(default_factory=FlightTimeouts)
    link_timeout_s: float | None = None
    """None: `WALL_LINK_TIMEOUT_S` on the wall clock, `LOCKSTEP_LINK_TIMEOUT_S` on the vehicle's."""
    arm_retry_period_s: float = 0.5
    altitude_tolerance_m: float = 0.3
    climb_done_speed_m_s: float = 0.2  # takeoff ends when the climb has (nearly) stopped
    takeoff_overshoot_m: float = 1.0
    """A takeoff that climbs this far above its altitude is stopped in Hold and raised
    (`TakeoffOvershootError`): copies of one NAV_TAKEOFF can each climb PX4 higher
    (`MavsdkVehicle.takeoff`)."""
    poll_s: float = 0.02
    expected_system_id: int | None = None
    shown_url: str | None = None
    """The vehicle's URL as the user gave it, for messages, when MAVSDK listens behind a relay elsewhere."""
    clock: str = "wall"  # or "vehicle": the autopilot's clock (see the module docstring)
    offboard_stream_period_s: float = 0.05
    """`clock="vehicle"`, in offboard: waits send the last setpoint again every this many seconds of the
    vehicle's clock. MAVSDK re-sends it at 20 Hz of wall time, which a vehicle k times faster than real
    time sees at 20/k Hz (PX4 wants more than 2 Hz), and a lockstepped sim-vehicle advances only as
    setpoints arrive: a stream on its own clock keeps both as at ×1."""
    landed_state_rate_hz: float | None = LANDED_STATE_HZ
    """Asked of the vehicle once connected and once ready (EXTENDED_SYS_STATE, SET_MESSAGE_INTERVAL):
    MAVSDK's Action plugin asks for 1 Hz when it starts, overriding the rate the vehicle was started with,
    and every takeoff and landing is confirmed from it (`drone_inspect_core.state_streams`). None: not
    asked."""
    parameter_save_guard_s: float = PX4_PARAMETER_SAVE_GUARD_S
    """Seconds (of `clock`) after the vehicle last armed or disarmed before `prepare_takeoff` sets a
    parameter: PX4 saves its parameters after either (see `PX4_PARAMETER_SAVE_GUARD_S`). 0: a vehicle that
    saves no parameters (`dronectl sim-vehicle` keeps them in memory)."""

    def __post_init__(self) -> None:
        validate_connection_url(self.url)
        if self.clock not in ("wall", "vehicle"):
            raise ValueError(f"MavsdkConfig.clock must be 'wall' or 'vehicle', got {self.clock!r}")
        if self.expected_system_id is not None and not 1 <= self.expected_system_id <= 255:
            raise ValueError(f"MavsdkConfig.expected_system_id must be 1..255, got {self.expected_system_id}")
        if not (self.link_timeout > 0 and self.arm_retry_period_s > 0 and self.poll_s > 0):
            raise ValueError("MavsdkConfig: link_timeout_s, arm_retry_period_s and poll_s must be > 0")
        if not self.offboard_stream_period_s > 0:
            raise ValueError("MavsdkConfig: offboard_stream_period_s must be > 0")
        if self.landed_state_rate_hz is not None and not 0 < self.landed_state_rate_hz <= 100:
            raise ValueError("MavsdkConfig: landed_state_rate_hz must be in (0, 100] or None")
        if not 0 <= self.parameter_save_guard_s < math.inf:
            raise ValueError("MavsdkConfig: parameter_save_guard_s must be >= 0")
        if not 0 < self.takeoff_overshoot_m < math.inf:
            raise ValueError("MavsdkConfig: takeoff_overshoot_m must be > 0")

    @property
    def link_timeout(self) -> float:
        """The link timeout in use (`link_timeout_s`, else the clock's default)."""
        if self.link_timeout_s is not None:
            return self.link_timeout_s
        return WALL_LINK_TIMEOUT_S if self.clock == "wall" else LOCKSTEP_LINK_TIMEOUT_S


COMMAND_ATTEMPTS = 3


def resend_on_timeout(
    call: Callable[[], Any],
    link: LinkMonitor | None = None,
    attempts: int = COMMAND_ATTEMPTS,
    taken: Callable[[], bool] | None = None,
) -> Any:
    """Run a MAVSDK command, sending it again when it timed out (every ack lost on a lossy link).

    MAVSDK already resends a command four times, 0.5 s apart, before TIMEOUT; on a radio that
    loses a fifth of the packets each way that still fails about once in 170 commands. Hold, land,
    disarm and offboard start/stop are idempotent on PX4, so sending them again is safe; a takeoff is
    not (`MavsdkVehicle.takeoff`), and passes `taken`: whether the vehicle already shows the command's
    effect, in which case a TIMEOUT lost only the acknowledgement and nothing is sent again. Any other
    result is raised at once. With `link`, a last TIMEOUT from a vehicle gone silent is a lost link
    (`LinkLostError`), not a refusal, and a vehicle already known lost is not sent the command again.
    """
    for attempt in range(1, attempts + 1):
        try:
            return call()
        except (ActionError, OffboardError) as exc:
            if exc.result.name == "TIMEOUT" and taken is not None and taken():
                log.info("%s timed out, but the vehicle shows it taken: not sent again", exc.origin)
                return None
            if exc.result.name != "TIMEOUT" or attempt == attempts:
                if exc.result.name == "TIMEOUT" and link is not None:
                    link.raise_if_lost(str(exc.origin))
                raise
            if link is not None:  # a vehicle known gone (its process exited, or silent past the timeout)
                link.check(str(exc.origin))  # gets no copy: each would wait out MAVSDK's own resends
            log.warning(
                "%s timed out (no ack): sending it again (%d of %d)", exc.origin, attempt + 1, attempts
            )
    return None


def route_mavsdk_logs() -> None:
    """Send the C library's log lines to Python logging instead of coloured stderr."""
    mavsdk_log = logging.getLogger("mavsdk")
    levels = {LogLevel.DEBUG: logging.DEBUG, LogLevel.INFO: logging.INFO, LogLevel.WARN: logging.WARNING}

    def forward(level: LogLevel, message: str, _file: str | None, _line: int) -> bool:
        mavsdk_log.log(levels.get(level, logging.ERROR), "%s", message)
        return True

    log_subscribe(forward)


class TelemetryCache:
    """The latest of every telemetry stream the backend reads, stored by MAVSDK's callback thread."""

    def __init__(
        self,
        link_timeout_s: float,
        connection_state: bool = True,
        peer_alive: Callable[[], bool] | None = None,
    ) -> None:
        self.lock = threading.Lock()
        self.position: tuple[float, float, float] = _NAN3
        self.velocity: tuple[float, float, float] = _NAN3
        self.attitude: tuple[float, float, float] = _NAN3
        self.armed = False
        self.armed_changed: tuple[float, float] = (-math.inf, -math.inf)
        """(vehicle clock, wall clock) when `armed` last changed."""
        self.in_air = False
        self.mode = FlightMode.UNKNOWN
        self.battery_percent: float | None = None
        self.local_position_ok = False
        self.home_ok = False
        self.global_position_ok = False
        self.texts = StatusTexts()
        self.vehicle_time_s = math.nan  # the autopilot's clock, from its ATTITUDE timestamps
        self.forward_range_m: float | None = None
        self.link = LinkMonitor(link_timeout_s, connection_state=connection_state, peer_alive=peer_alive)

    def subscribe(self, system: Any, tel: MavsdkTelemetry) -> None:
        def store(fn: Callable[[Any], None]) -> Callable[[Any, Any], None]:
            def callback(data: Any, _user_data: Any) -> None:
                with self.lock:
                    fn(data)
                self.link.heard()

            return callback

        def pos_vel(d: Any) -> None:
            self.position = (d.position.north_m, d.position.east_m, d.position.down_m)
            self.velocity = (d.velocity.north_m_s, d.velocity.east_m_s, d.velocity.down_m_s)

        def attitude(d: Any) -> None:
            self.attitude = (d.roll_deg, d.pitch_deg, d.yaw_deg)
            stamp_s = d.timestamp_us * 1e-6 if d.timestamp_us else math.nan
            if not stamp_s <= self.vehicle_time_s:  # the first stamp, or a newer one (never backwards)
                self.vehicle_time_s = stamp_s

        def health(d: Any) -> None:
            self.local_position_ok, self.home_ok = d.is_local_position_ok, d.is_home_position_ok
            self.global_position_ok = d.is_global_position_ok

        def battery(d: Any) -> None:
            self.battery_percent = None if math.isnan(d.remaining_percent) else d.remaining_percent

        def distance(d: Any) -> None:
            o = d.orientation  # MAVSDK turns MAV_SENSOR_ORIENTATION into Euler angles: forward is all zero
            if abs(o.roll_deg) > 1.0 or abs(o.pitch_deg) > 1.0 or abs(o.yaw_deg) > 1.0:
                return  # a downward (height) or sideways sensor: not the one that sees the target
            current = d.current_distance_m
            in_range = d.minimum_distance_m <= current <= d.maximum_distance_m
            self.forward_range_m = float(current) if in_range else None

        def status_text(d: Any) -> None:
            self.texts.add(f"{d.type.name}: {d.text}")

        tel.subscribe_position_velocity_ned(store(pos_vel))
        tel.subscribe_attitude_euler(store(attitude))

        def armed(d: Any) -> None:
            if bool(d) != self.armed:
                self.armed_changed = (self.vehicle_time_s, time.monotonic())
            self.armed = bool(d)

        tel.subscribe_armed(store(armed))
        tel.subscribe_in_air(store(lambda d: setattr(self, "in_air", bool(d))))
        tel.subscribe_flight_mode(
            store(lambda d: setattr(self, "mode", FlightMode.__members__.get(d.name, FlightMode.OTHER)))
        )
        tel.subscribe_health(store(health))
        tel.subscribe_battery(store(battery))
        tel.subscribe_status_text(store(status_text))
        tel.subscribe_distance_sensor(store(distance))
        system.subscribe_is_connected(lambda connected, _ud: self.link.set_connected(bool(connected)))

    def snapshot(self, timestamp_s: float) -> Telemetry:
        with self.lock:
            return Telemetry(
                position_ned=PositionNed(*self.position),
                velocity_ned=VelocityNed(*self.velocity),
                attitude=Attitude(*self.attitude),
                armed=self.armed,
                in_air=self.in_air,
                flight_mode=self.mode,
                timestamp_s=timestamp_s,
                battery_remaining_percent=self.battery_percent,
                forward_range_m=self.forward_range_m,
            )
