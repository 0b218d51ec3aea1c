"""`SafeVehicle`: any `Vehicle` behind the safety limits, a geofence and a setpoint watchdog.

Every velocity command is clipped to `SafetyLimits` (and stripped of components
that would leave the geofence) before it reaches the backend. The watchdog
commands zero velocity when the controller stops commanding in offboard for
longer than `setpoint_timeout_s`: a hung planner must not leave the vehicle
flying its last setpoint (MAVSDK keeps re-sending that setpoint on its own).
For a real-time link the watchdog is a daemon thread; for a simulated-time
backend it runs inside `sleep()`, the only place where that clock advances.
"""

from __future__ import annotations

import logging
import threading

from flight.errors import FlightError, GeofenceBreachError
from flight.safety import SafetyLimits, clip_geofence, clip_speed
from flight.types import ZERO_VELOCITY, PositionNed, Telemetry, VelocityBody
from flight.vehicle import Vehicle

log = logging.getLogger(__name__)

_WATCHDOG_PERIOD_S = 0.05


class SafeVehicle(Vehicle):
    """Wraps `inner`; fills every omitted timeout from `limits.timeouts`."""

    def __init__(self, inner: Vehicle, limits: SafetyLimits | None = None) -> None:
        self.inner = inner
        self.limits = limits or SafetyLimits()
        self.realtime = inner.realtime
        self.wall_paced_telemetry = inner.wall_paced_telemetry
        self.origin: PositionNed | None = None
        self.last_command: VelocityBody = ZERO_VELOCITY
        self.watchdog_trips = 0
        self._last_command_time_s = 0.0
        self._offboard = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- the guarded commands ---------------------------------------------------------------
    def set_velocity_body(self, velocity: VelocityBody) -> None:
        command = clip_speed(velocity, self.limits)
        fence = self.limits.geofence
        if fence is not None and self.origin is not None:
            telemetry = self.inner.telemetry()
            excess = fence.excess_m(telemetry.position_ned, self.origin)
            if excess > fence.breach_margin_m:
                self._command(ZERO_VELOCITY)
                raise GeofenceBreachError(
                    "set_velocity_body()",
                    "GEOFENCE_BREACH",
                    f"{excess:.2f} m outside the box at {telemetry.position_ned}",
                )
            command = clip_geofence(command, telemetry, self.origin, fence)
        if command != velocity:
            log.info("velocity command %s limited to %s", velocity, command)
        self._command(command)

    def _command(self, command: VelocityBody) -> None:
        with self._lock:
            self.inner.set_velocity_body(command)
            self.last_command = command
            self._last_command_time_s = self.inner.time_s()

    def setpoint_age_s(self) -> float | None:
        """Seconds (vehicle clock) since the last velocity setpoint reached the backend, while in offboard
        (where the watchdog counts it); None outside offboard."""
        with self._lock:
            return self.inner.time_s() - self._last_command_time_s if self._offboard else None

    def watchdog_tick(self) -> bool:
        """Command zero velocity if the controller went silent in offboard; True when it did."""
        with self._lock:
            silent_s = self.inner.time_s() - self._last_command_time_s
            if (
                not self._offboard
                or self.last_command.is_zero()
                or silent_s <= self.limits.setpoint_timeout_s
            ):
                return False
            log.warning("no velocity command for %.2f s in offboard: commanding zero velocity", silent_s)
            self.last_command = ZERO_VELOCITY
            self.watchdog_trips += 1
            try:
                self.inner.set_velocity_body(ZERO_VELOCITY)
            except FlightError as exc:  # offboard already lost, or the link: nothing left to stop here
                log.error("setpoint watchdog could not command zero velocity: %s", exc)
                self._offboard = False
            return True

    def _watchdog_loop(self) -> None:
        while not self._stop.wait(_WATCHDOG_PERIOD_S):
            try:
                self.watchdog_tick()
            except Exception:  # the thread must not die silently while the vehicle flies
                log.exception("setpoint watchdog tick failed")

    def _start_watchdog(self) -> None:
        if not self.realtime or self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._watchdog_loop, name="setpoint-watchdog", daemon=True)
        self._thread.start()

    def _stop_watchdog(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None

    # --- delegation with default timeouts ---------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        self.inner.connect(timeout_s or self.limits.timeouts.connect_s)

    def wait_ready(self, timeout_s: float | None = None) -> None:
        self.inner.wait_ready(timeout_s or self.limits.timeouts.ready_s)

    def prepare_takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self.inner.prepare_takeoff(altitude_m, timeout_s or self.limits.timeouts.arm_s)

    def arm(self, timeout_s: float | None = None) -> None:
        self.inner.arm(timeout_s or self.limits.timeouts.arm_s)
        if self.origin is None:
            self.origin = self.inner.telemetry().position_ned
            log.info("geofence origin set at %s", self.origin)

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        fence = self.limits.geofence
        if fence is not None and altitude_m > fence.max_up_m:
            raise GeofenceBreachError(
                "takeoff()",
                "GEOFENCE_BREACH",
                f"altitude {altitude_m} m above the fence's {fence.max_up_m} m",
            )
        self.inner.takeoff(altitude_m, timeout_s or self.limits.timeouts.takeoff_s)

    def start_offboard(self, timeout_s: float | None = None) -> None:
        self.inner.start_offboard(timeout_s or self.limits.timeouts.mode_change_s)
        with self._lock:
            self._offboard = True
            self._last_command_time_s = self.inner.time_s()
        self._start_watchdog()

    def hold(self) -> None:
        with self._lock:
            self.inner.hold()
            self.last_command = ZERO_VELOCITY
            self._last_command_time_s = self.inner.time_s()

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self._leave_offboard()
        self.inner.stop_offboard(timeout_s or self.limits.timeouts.mode_change_s)

    def land(self, timeout_s: float | None = None) -> None:
        self._leave_offboard()
        self.inner.land(timeout_s or self.limits.timeouts.land_s)

    def _leave_offboard(self) -> None:
        self._stop_watchdog()
        with self._lock:
            self._offboard = False

    def disarm(self, timeout_s: float | None = None) -> None:
        self.inner.disarm(timeout_s or self.limits.timeouts.disarm_s)

    def kill(self, timeout_s: float | None = None) -> None:
        self._leave_offboard()
        self.inner.kill(timeout_s or self.limits.timeouts.disarm_s)

    def send_land(self) -> bool:
        self._leave_offboard()
        return self.inner.send_land()

    def telemetry(self) -> Telemetry:
        return self.inner.telemetry()

    def time_s(self) -> float:
        return self.inner.time_s()

    def sleep(self, seconds: float) -> None:
        if self.realtime:
            self.inner.sleep(seconds)
            return
        remaining = seconds
        while remaining > 1e-9:
            chunk = min(remaining, _WATCHDOG_PERIOD_S)
            self.inner.sleep(chunk)
            remaining -= chunk
            self.watchdog_tick()

    def status_texts(self) -> list[str]:
        return self.inner.status_texts()

    def close(self) -> None:
        self._stop_watchdog()
        self.inner.close()
