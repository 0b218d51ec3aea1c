"""`MavsdkVehicle`: the `Vehicle` interface over MAVLink with MAVSDK 4 (the only module importing mavsdk).

Written for real PX4 (SITL or hardware) as much as for `dronectl sim-vehicle`:
- arming is retried while PX4 refuses it for a few seconds after boot (MAVSDK
  reports both DENIED and TEMPORARILY_REJECTED as COMMAND_DENIED, so every
  refusal is retried until the arm deadline, then raised with PX4's last message);
- every mode change is confirmed from the flight mode in telemetry (PX4 can ack
  ACCEPTED and then refuse), never from the ack alone;
- offboard is left for Hold before landing (else PX4 returns to OFFBOARD after
  disarm and refuses the next arm); a disarm racing PX4's auto-disarm is success.
- MAVSDK re-sends the last setpoint at 20 Hz by itself: `set_velocity_body` is
  called only when the command changes or the caller refreshes it, never in a loop.
- link loss (no telemetry for `link_timeout_s`, or MAVSDK's connection state
  going false) raises `LinkLostError` from `telemetry()` and so from every wait;
- `expected_system_id`: connect only to the autopilot with that MAVLink system id
  (the per-run identity of a vehicle the caller launched) and refuse any other;
- `clock="vehicle"`: `time_s()`/`sleep()` follow the autopilot's own clock (the
  `time_boot_ms` of its ATTITUDE stream) instead of the wall clock, for a simulated
  autopilot running faster or slower than real time in lockstep (PX4 SITL).

MAVSDK's sync callbacks all run on one MAVSDK thread, and blocking calls return
through it: the callbacks here only store values under a lock.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk, log_subscribe
from mavsdk.logging import LogLevel
from mavsdk.plugins.action import Action, ActionError, ActionResult
from mavsdk.plugins.offboard import Offboard, OffboardError, VelocityBodyYawspeed
from mavsdk.plugins.telemetry import Telemetry as MavsdkTelemetry

from flight.errors import (
    CommandDeniedError,
    FlightTimeoutError,
    ModeChangeError,
    OffboardInterruptedError,
    VehicleConnectionError,
)
from flight.link import LinkMonitor
from flight.safety import FlightTimeouts
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityBody, VelocityNed
from flight.urls import validate_connection_url
from flight.vehicle import Vehicle, wait_for

log = logging.getLogger(__name__)

_RETRY_ARM = {ActionResult.COMMAND_DENIED, ActionResult.BUSY, ActionResult.TIMEOUT, ActionResult.FAILED}
_NAN3 = (math.nan, math.nan, math.nan)
READY_REPORT_EVERY_S = 5.0
DISARM_RACE_WAIT_S = 3.0


@dataclass(frozen=True)
class MavsdkConfig:
    """How to reach the vehicle and how long to wait for it."""

    url: str = "udpin://0.0.0.0:14540"
    timeouts: FlightTimeouts = field(default_factory=FlightTimeouts)
    link_timeout_s: float = 2.0
    arm_retry_period_s: float = 0.5
    altitude_tolerance_m: float = 0.3
    climb_done_speed_m_s: float = 0.2  # takeoff ends when the climb has (nearly) stopped
    poll_s: float = 0.02
    expected_system_id: int | None = None
    shown_url: str | None = None
    """The vehicle's URL as the user gave it, for messages, when MAVSDK listens behind a relay elsewhere."""
    clock: str = "wall"  # or "vehicle": the autopilot's clock (see the module docstring)

    def __post_init__(self) -> None:
        validate_connection_url(self.url)
        if self.clock not in ("wall", "vehicle"):
            raise ValueError(f"MavsdkConfig.clock must be 'wall' or 'vehicle', got {self.clock!r}")
        if self.expected_system_id is not None and not 1 <= self.expected_system_id <= 255:
            raise ValueError(f"MavsdkConfig.expected_system_id must be 1..255, got {self.expected_system_id}")
        if not (self.link_timeout_s > 0 and self.arm_retry_period_s > 0 and self.poll_s > 0):
            raise ValueError("MavsdkConfig: link_timeout_s, arm_retry_period_s and poll_s must be > 0")


COMMAND_ATTEMPTS = 3


def _resend_on_timeout(call: Callable[[], Any], attempts: int = COMMAND_ATTEMPTS) -> Any:
    """Run a MAVSDK command, sending it again when it timed out (every ack lost on a lossy link).

    MAVSDK already resends a command four times, 0.5 s apart, before TIMEOUT; on a radio that
    loses a fifth of the packets each way that still fails about once in 170 commands. These
    commands (takeoff, hold, land, disarm, offboard start/stop) are idempotent on PX4, so sending
    them again is safe. Any other result is raised at once.
    """
    for attempt in range(1, attempts + 1):
        try:
            return call()
        except (ActionError, OffboardError) as exc:
            if exc.result.name != "TIMEOUT" or attempt == attempts:
                raise
            log.warning(
                "%s timed out (no ack): sending it again (%d of %d)", exc.origin, attempt + 1, attempts
            )
    return None


def _route_mavsdk_logs() -> None:
    """Send the C library's log lines to Python logging instead of coloured stderr."""
    mavsdk_log = logging.getLogger("mavsdk")
    levels = {LogLevel.DEBUG: logging.DEBUG, LogLevel.INFO: logging.INFO, LogLevel.WARN: logging.WARNING}

    def forward(level: LogLevel, message: str, _file: str | None, _line: int) -> bool:
        mavsdk_log.log(levels.get(level, logging.ERROR), "%s", message)
        return True

    log_subscribe(forward)


class MavsdkVehicle(Vehicle):
    """A PX4-style vehicle reached through MAVSDK at `config.url`."""

    realtime = True

    def __init__(self, config: MavsdkConfig | None = None) -> None:
        self.config = config or MavsdkConfig()
        self.setpoints_sent = 0
        self._lock = threading.Lock()
        self._position: tuple[float, float, float] = _NAN3
        self._velocity: tuple[float, float, float] = _NAN3
        self._attitude: tuple[float, float, float] = _NAN3
        self._armed = False
        self._in_air = False
        self._mode = FlightMode.UNKNOWN
        self._battery_percent: float | None = None
        self._local_position_ok = False
        self._home_ok = False
        self._texts: deque[str] = deque(maxlen=100)
        self._texts_received = 0  # all STATUSTEXTs so far (the deque keeps the latest only)
        self._texts_at_offboard = 0  # the count when offboard was confirmed
        self._link = LinkMonitor(self.config.link_timeout_s)
        self._mavsdk: Mavsdk | None = None
        self._system: Any = None
        self._telemetry: MavsdkTelemetry | None = None
        self._action: Action | None = None
        self._offboard: Offboard | None = None
        self._setpoint_set = False
        self._in_offboard = False
        self._ground_down_m = math.nan
        self._vehicle_time_s = math.nan  # the autopilot's clock, from its ATTITUDE timestamps

    # --- connection ---------------------------------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        if self._mavsdk is not None:
            return
        timeout_s = timeout_s or self.config.timeouts.connect_s
        url = self.config.url
        _route_mavsdk_logs()
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        result = self._mavsdk.add_any_connection(url)
        if result != ConnectionResult.SUCCESS:
            hint = (
                " (is another program already bound to that port?)"
                if result == ConnectionResult.BIND_ERROR
                else ""
            )
            self.close()
            raise VehicleConnectionError("connect()", result.name, f"cannot open {self._where()}{hint}")
        system = (
            self._mavsdk.first_autopilot(timeout_s)
            if self.config.expected_system_id is None
            else self._autopilot_with_id(self.config.expected_system_id, timeout_s)
        )
        if system is None:
            self.close()
            raise VehicleConnectionError(
                "connect()",
                "NO_AUTOPILOT",
                f"no autopilot heartbeat on {self._where()} within {timeout_s:.1f} s: is the vehicle "
                "running and sending to this address and port? (PX4 SITL and `dronectl sim-vehicle` send "
                "to 14540 by default)",
            )
        self._link = LinkMonitor(self.config.link_timeout_s)
        # Keep every MAVSDK object referenced for the connection's life: a plugin left to the
        # garbage collector is destroyed with its subscriptions, and telemetry silently stops.
        self._system = system
        self._telemetry = MavsdkTelemetry(system)
        self._action = Action(system)
        self._offboard = Offboard(system)
        self._subscribe(system, self._telemetry)
        if self.config.clock == "vehicle":
            deadline = time.monotonic() + timeout_s
            while math.isnan(self._vehicle_time_s):
                if time.monotonic() > deadline:
                    self.close()
                    raise VehicleConnectionError(
                        "connect()", "NO_VEHICLE_CLOCK", f"no timestamped ATTITUDE within {timeout_s:.1f} s"
                    )
                time.sleep(0.01)
        log.info("connected to an autopilot on %s (system id %d)", url, system.get_system_id())

    def _where(self) -> str:
        """The URL for messages: the user's, and where MAVSDK really listens if that differs."""
        shown, url = self.config.shown_url, self.config.url
        return url if shown is None or shown == url else f"{shown} (relayed to MAVSDK on {url})"

    def _autopilot_with_id(self, system_id: int, timeout_s: float) -> Any:
        """The autopilot with this system id; VehicleConnectionError naming any other that answered."""
        assert self._mavsdk is not None
        deadline = time.monotonic() + timeout_s
        others: set[int] = set()
        while time.monotonic() < deadline:
            for system in self._mavsdk.get_systems():
                sid = system.get_system_id()
                if sid == system_id and system.has_autopilot():
                    return system
                if sid != system_id:
                    others.add(sid)
            time.sleep(0.05)
        if others:
            self.close()
            raise VehicleConnectionError(
                "connect()",
                "WRONG_VEHICLE",
                f"{self._where()}: heard system id {sorted(others)} but not {system_id}, the vehicle "
                "this run launched: refusing to fly another vehicle",
            )
        return None

    def _subscribe(self, system: Any, tel: MavsdkTelemetry) -> None:
        def store(fn: Callable[[Any], None]) -> Callable[[Any, Any], None]:
            def callback(data: Any, _user_data: Any) -> None:
                with self._lock:
                    fn(data)
                self._link.heard()

            return callback

        def pos_vel(d: Any) -> None:
            self._position = (d.position.north_m, d.position.east_m, d.position.down_m)
            self._velocity = (d.velocity.north_m_s, d.velocity.east_m_s, d.velocity.down_m_s)

        def attitude(d: Any) -> None:
            self._attitude = (d.roll_deg, d.pitch_deg, d.yaw_deg)
            stamp_s = d.timestamp_us * 1e-6 if d.timestamp_us else math.nan
            if not stamp_s <= self._vehicle_time_s:  # the first stamp, or a newer one (never backwards)
                self._vehicle_time_s = stamp_s

        def health(d: Any) -> None:
            self._local_position_ok, self._home_ok = d.is_local_position_ok, d.is_home_position_ok

        def battery(d: Any) -> None:
            self._battery_percent = None if math.isnan(d.remaining_percent) else d.remaining_percent

        tel.subscribe_position_velocity_ned(store(pos_vel))
        tel.subscribe_attitude_euler(store(attitude))
        tel.subscribe_armed(store(lambda d: setattr(self, "_armed", bool(d))))
        tel.subscribe_in_air(store(lambda d: setattr(self, "_in_air", bool(d))))
        tel.subscribe_flight_mode(
            store(lambda d: setattr(self, "_mode", FlightMode.__members__.get(d.name, FlightMode.OTHER)))
        )
        tel.subscribe_health(store(health))
        tel.subscribe_battery(store(battery))

        def status_text(d: Any) -> None:
            self._texts.append(f"{d.type.name}: {d.text}")
            self._texts_received += 1

        tel.subscribe_status_text(store(status_text))
        system.subscribe_is_connected(lambda connected, _ud: self._link.set_connected(bool(connected)))

    # --- telemetry ----------------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        self._link.check("telemetry()")
        with self._lock:
            return Telemetry(
                position_ned=PositionNed(*self._position),
                velocity_ned=VelocityNed(*self._velocity),
                attitude=Attitude(*self._attitude),
                armed=self._armed,
                in_air=self._in_air,
                flight_mode=self._mode,
                timestamp_s=self.time_s(),
                battery_remaining_percent=self._battery_percent,
            )

    def status_texts(self) -> list[str]:
        with self._lock:
            return list(self._texts)

    def _last_text(self) -> str:
        with self._lock:
            return self._texts[-1] if self._texts else ""

    def _texts_since_offboard(self) -> str:
        """What the vehicle said since offboard began ("; "-joined): a failsafe sends several texts,
        and the one naming the cause ("No offboard signal") need not be the last by the time the
        heartbeat shows the mode change."""
        with self._lock:
            new = min(self._texts_received - self._texts_at_offboard, len(self._texts))
            return "; ".join(list(self._texts)[len(self._texts) - new :]) if new > 0 else ""

    def time_s(self) -> float:
        if self.config.clock == "vehicle":
            return self._vehicle_time_s  # one float, written whole by the MAVSDK thread: no lock needed
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if self.config.clock == "wall":
            time.sleep(max(0.0, seconds))
            return
        until = self.time_s() + seconds
        while self.time_s() < until:
            self._link.check("sleep()")  # a frozen vehicle clock ends here, as a lost link
            time.sleep(0.002)

    def _wait(
        self, predicate: Callable[[Telemetry], bool], timeout_s: float, origin: str, what: str
    ) -> Telemetry:
        return wait_for(self, predicate, timeout_s, origin, what, poll_s=self.config.poll_s)

    # --- commands -----------------------------------------------------------------------------
    def wait_ready(self, timeout_s: float | None = None) -> None:
        """Wait for PX4's estimator: a local position and a home position (PX4 SITL with SIH: 31-35 s)."""
        timeout_s = timeout_s or self.config.timeouts.ready_s
        start = self.time_s()
        next_report = start + READY_REPORT_EVERY_S

        def ready(t: Telemetry) -> bool:
            nonlocal next_report
            with self._lock:
                position_ok, home_ok = self._local_position_ok, self._home_ok
            ok = position_ok and home_ok and math.isfinite(t.position_ned.down_m)
            ok = ok and math.isfinite(t.attitude.yaw_deg)
            if not ok and self.time_s() >= next_report:
                next_report += READY_REPORT_EVERY_S
                log.info(
                    "waiting for the vehicle's estimator (%.0f of %.0f s): local position %s, home %s",
                    self.time_s() - start, timeout_s, "ok" if position_ok else "not yet",
                    "ok" if home_ok else "not yet",
                )  # fmt: skip
            return ok

        telemetry = self._wait(ready, timeout_s, "wait_ready()", "local position + home")
        self._ground_down_m = telemetry.position_ned.down_m

    def arm(self, timeout_s: float | None = None) -> None:
        timeout_s = timeout_s or self.config.timeouts.arm_s
        action = self._require(self._action, "arm()")
        deadline = self.time_s() + timeout_s
        if self.telemetry().flight_mode == FlightMode.OFFBOARD:
            # PX4 reverts to the last requested mode after a disarm and refuses to arm in OFFBOARD.
            log.info("disarmed in OFFBOARD (PX4 reverted to it after the last flight): switching to Hold")
            self.hold()
        while True:
            self._link.check("arm()")
            try:
                action.arm()
                break
            except ActionError as exc:
                if exc.result not in _RETRY_ARM or self.time_s() + self.config.arm_retry_period_s > deadline:
                    raise CommandDeniedError("arm()", exc.result.name, self._last_text()) from None
                log.info("arming refused (%s; %r): retrying", exc.result.name, self._last_text())
                self.sleep(self.config.arm_retry_period_s)
        self._wait(lambda t: t.armed, max(0.5, deadline - self.time_s()), "arm()", "armed state in telemetry")
        if not math.isfinite(self._ground_down_m):
            self._ground_down_m = self.telemetry().position_ned.down_m

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        action = self._require(self._action, "takeoff()")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude must be a positive number of metres, got {altitude_m!r}")
        try:
            _resend_on_timeout(lambda: action.set_takeoff_altitude(altitude_m))
            _resend_on_timeout(action.takeoff)
        except ActionError as exc:
            armed = self.telemetry().armed
            detail = self._last_text() or ("the vehicle is not armed" if not armed else "")
            raise CommandDeniedError(exc.origin, exc.result.name, detail) from None
        target_m = altitude_m - self.config.altitude_tolerance_m
        # Done when PX4 says so (it leaves TAKEOFF for HOLD at the altitude), not merely when the
        # climb is slow: a low takeoff (0.5 m) rises slowly all the way, and was taken for finished
        # 0.3 m short of it.
        self._wait(
            lambda t: (
                t.in_air
                and t.flight_mode != FlightMode.TAKEOFF
                and self._ground_down_m - t.position_ned.down_m >= target_m
                and abs(t.velocity_ned.down_m_s) < self.config.climb_done_speed_m_s
            ),
            timeout_s or self.config.timeouts.takeoff_s,
            "takeoff()",
            f"in-air state, altitude {target_m:.2f} m, the takeoff mode left and the climb ending",
        )

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        offboard = self._require(self._offboard, "set_velocity_body()")
        self._check_still_offboard("set_velocity_body()")
        setpoint = VelocityBodyYawspeed(
            velocity.forward_m_s, velocity.right_m_s, velocity.down_m_s, velocity.yawspeed_deg_s
        )
        try:
            offboard.set_velocity_body(setpoint)
        except OffboardError as exc:
            raise CommandDeniedError("set_velocity_body()", exc.result.name) from None
        self._setpoint_set = True
        self.setpoints_sent += 1

    def _check_still_offboard(self, origin: str) -> None:
        """Report a vehicle that left offboard by itself (PX4's setpoint-loss failsafe, a pilot's switch)."""
        mode = self.telemetry().flight_mode
        if self._in_offboard and mode != FlightMode.OFFBOARD:
            self._in_offboard = False
            raise OffboardInterruptedError(
                origin, mode.name, self._texts_since_offboard() or self._last_text()
            )

    def start_offboard(self, timeout_s: float | None = None) -> None:
        offboard = self._require(self._offboard, "start_offboard()")
        if not self._setpoint_set:
            raise CommandDeniedError(
                "start_offboard()",
                "NO_SETPOINT_SET",
                "set a velocity setpoint first: PX4 needs a setpoint stream",
            )
        try:
            _resend_on_timeout(offboard.start)
        except OffboardError as exc:
            raise CommandDeniedError("start_offboard()", exc.result.name, self._last_text()) from None
        self._confirm_mode(FlightMode.OFFBOARD, timeout_s, "start_offboard()")
        with self._lock:
            self._texts_at_offboard = self._texts_received
        self._in_offboard = True

    def hold(self) -> None:
        if self._in_offboard and self.telemetry().flight_mode == FlightMode.OFFBOARD:
            self.set_velocity_body(VelocityBody())
            return
        self._in_offboard = False
        action = self._require(self._action, "hold()")
        try:
            _resend_on_timeout(action.hold)
        except ActionError as exc:
            raise CommandDeniedError("hold()", exc.result.name, self._last_text()) from None
        self._confirm_mode(FlightMode.HOLD, None, "hold()")

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        offboard = self._require(self._offboard, "stop_offboard()")
        self._in_offboard = False
        if self.telemetry().flight_mode != FlightMode.OFFBOARD:
            return
        try:
            _resend_on_timeout(offboard.stop)
        except OffboardError as exc:
            raise CommandDeniedError("stop_offboard()", exc.result.name, self._last_text()) from None
        self._confirm_mode(FlightMode.HOLD, timeout_s, "stop_offboard()")

    def land(self, timeout_s: float | None = None) -> None:
        action = self._require(self._action, "land()")
        if self.telemetry().flight_mode == FlightMode.OFFBOARD:
            self.stop_offboard()
        self._in_offboard = False
        try:
            _resend_on_timeout(action.land)
        except ActionError as exc:
            raise CommandDeniedError("land()", exc.result.name, self._last_text()) from None
        self._wait(lambda t: not t.in_air, timeout_s or self.config.timeouts.land_s, "land()", "landed state")

    def disarm(self, timeout_s: float | None = None) -> None:
        action = self._require(self._action, "disarm()")
        if not self.telemetry().armed:
            return
        try:
            _resend_on_timeout(action.disarm)
        except ActionError as exc:
            # PX4's auto-disarm may have won the race (its ack lost, or telemetry a heartbeat late):
            # that is success, so give telemetry a moment to say so before calling it a failure.
            try:
                self._wait(lambda t: not t.armed, DISARM_RACE_WAIT_S, "disarm()", "disarmed state")
            except FlightTimeoutError:
                raise CommandDeniedError("disarm()", exc.result.name, self._last_text()) from None
        self._wait(
            lambda t: not t.armed, timeout_s or self.config.timeouts.disarm_s, "disarm()", "disarmed state"
        )

    def _confirm_mode(self, mode: FlightMode, timeout_s: float | None, origin: str) -> None:
        timeout_s = timeout_s or self.config.timeouts.mode_change_s
        deadline = self.time_s() + timeout_s
        while (observed := self.telemetry().flight_mode) != mode:
            if self.time_s() >= deadline:
                raise ModeChangeError(
                    origin, mode.name, f"{observed.name} ({self._last_text()!r})", timeout_s
                )
            self.sleep(self.config.poll_s)

    # --- diagnostics and teardown -------------------------------------------------------------
    def command_round_trip_s(self) -> float:
        """Time one harmless command (Hold while already holding) from send to ack: a link benchmark."""
        action = self._require(self._action, "command_round_trip_s()")
        start = time.perf_counter()
        action.hold()
        return time.perf_counter() - start

    def _require(self, plugin: Any, origin: str) -> Any:
        if plugin is None:
            raise CommandDeniedError(origin, "NOT_CONNECTED", "call connect() first")
        return plugin

    def close(self) -> None:
        mavsdk, self._mavsdk = self._mavsdk, None
        self._action = self._offboard = self._telemetry = self._system = None
        if mavsdk is not None:
            mavsdk.destroy()
