"""What an ArduCopter vehicle says about itself, kept up to date from its MAVLink stream.

ArduCopter's flight modes are HEARTBEAT `custom_mode` numbers (STABILIZE 0, ACRO 1, ALT_HOLD 2, AUTO 3,
GUIDED 4, LOITER 5, RTL 6, CIRCLE 7, LAND 9, DRIFT 11, SPORT 13, POSHOLD 16, BRAKE 17, SMART_RTL 21,
...); `flight_mode_of` maps them onto the flight interface's `FlightMode` the way MAVSDK reports
ArduPilot: GUIDED is OFFBOARD (setpoints steer it), BRAKE and LOITER are HOLD.

Sources: armed and mode from HEARTBEAT (base_mode bit 128, custom_mode); landed state from
EXTENDED_SYS_STATE; position and velocity from LOCAL_POSITION_NED; attitude from ATTITUDE; the estimator
from EKF_STATUS_REPORT; home from HOME_POSITION; the pre-arm verdict from SYS_STATUS's
MAV_SYS_STATUS_PREARM_CHECK health bit; the autopilot's clock from `time_boot_ms` (ArduPilot SITL's
is simulated time). Handlers run on the link's reader thread and only store values under a lock.
"""

from __future__ import annotations

import math
import threading
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from flight.status_texts import StatusTexts
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityNed

COPTER_MODES = {
    "STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "CIRCLE": 7,
    "LAND": 9, "DRIFT": 11, "SPORT": 13, "FLIP": 14, "AUTOTUNE": 15, "POSHOLD": 16, "BRAKE": 17,
    "THROW": 18, "AVOID_ADSB": 19, "GUIDED_NOGPS": 20, "SMART_RTL": 21, "FLOWHOLD": 22, "FOLLOW": 23,
    "ZIGZAG": 24, "SYSTEMID": 25, "AUTOROTATE": 26, "AUTO_RTL": 27, "TURTLE": 28,
}  # fmt: skip
COPTER_MODE_NAMES = {number: name for name, number in COPTER_MODES.items()}
GUIDED = COPTER_MODES["GUIDED"]
LAND = COPTER_MODES["LAND"]
HOLD_MODES = ("BRAKE", "LOITER")
_FLIGHT_MODES = {
    "GUIDED": FlightMode.OFFBOARD, "BRAKE": FlightMode.HOLD, "LOITER": FlightMode.HOLD,
    "LAND": FlightMode.LAND, "RTL": FlightMode.RETURN_TO_LAUNCH, "SMART_RTL": FlightMode.RETURN_TO_LAUNCH,
    "AUTO_RTL": FlightMode.RETURN_TO_LAUNCH, "AUTO": FlightMode.MISSION, "STABILIZE": FlightMode.MANUAL,
    "ACRO": FlightMode.MANUAL, "ALT_HOLD": FlightMode.ALTCTL, "POSHOLD": FlightMode.POSCTL,
}  # fmt: skip

EKF_READY_FLAGS = (
    mavlink.EKF_ATTITUDE
    | mavlink.EKF_VELOCITY_HORIZ
    | mavlink.EKF_VELOCITY_VERT
    | mavlink.EKF_POS_HORIZ_REL
    | mavlink.EKF_POS_HORIZ_ABS
    | mavlink.EKF_POS_VERT_ABS
)
"""An estimate good for GUIDED flight: attitude, velocities, horizontal position (relative and
absolute) and height; and not in constant-position mode (EKF_CONST_POS_MODE, checked apart)."""
_IN_AIR_STATES = (
    mavlink.MAV_LANDED_STATE_IN_AIR,
    mavlink.MAV_LANDED_STATE_TAKEOFF,
    mavlink.MAV_LANDED_STATE_LANDING,
)
_NAN3 = (math.nan, math.nan, math.nan)


def mode_name(custom_mode: int | None) -> str:
    if custom_mode is None:
        return "UNKNOWN"
    return COPTER_MODE_NAMES.get(custom_mode, f"MODE_{custom_mode}")


def flight_mode_of(custom_mode: int | None) -> FlightMode:
    if custom_mode is None:
        return FlightMode.UNKNOWN
    return _FLIGHT_MODES.get(mode_name(custom_mode), FlightMode.OTHER)


class ArduPilotState:
    """The latest of everything the backend reads, for the one vehicle `system_id` (set on connect)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.system_id: int | None = None
        self.heard_autopilots: dict[int, tuple[int, int]] = {}  # system id -> (MAV_AUTOPILOT, MAV_TYPE)
        self.heartbeats = 0
        self.armed = False
        self.custom_mode: int | None = None
        self.system_status = 0
        self.landed_state = mavlink.MAV_LANDED_STATE_UNDEFINED
        self.position = _NAN3
        self.velocity = _NAN3
        self.attitude = _NAN3
        self.ekf_flags = 0
        self.ekf_reports = 0
        self.home_ok = False
        self.prearm_ok: bool | None = None
        self.battery_percent: float | None = None
        self.forward_range_m: float | None = None
        self.vehicle_time_s = math.nan
        self.seen: set[str] = set()
        self.texts = StatusTexts()

    # ------------------------------------------------------------------ from the reader thread
    def handle(self, msg: Any) -> None:
        kind = msg.get_type()
        source = msg.get_srcSystem()
        autopilot = kind == "HEARTBEAT" and msg.type != mavlink.MAV_TYPE_GCS
        if autopilot and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
            with self.lock:
                self.heard_autopilots[source] = (msg.autopilot, msg.type)
        if source != self.system_id or msg.get_srcComponent() != mavlink.MAV_COMP_ID_AUTOPILOT1:
            return
        with self.lock:
            self.seen.add(kind)
            if autopilot:
                self.heartbeats += 1
                self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                self.custom_mode = msg.custom_mode
                self.system_status = msg.system_status
            elif kind == "ATTITUDE":
                self.attitude = tuple(math.degrees(v) for v in (msg.roll, msg.pitch, msg.yaw))  # type: ignore[assignment]
                self._clock(msg.time_boot_ms)
            elif kind == "LOCAL_POSITION_NED":
                self.position, self.velocity = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
                self._clock(msg.time_boot_ms)
            elif kind == "EXTENDED_SYS_STATE":
                self.landed_state = msg.landed_state
            elif kind == "EKF_STATUS_REPORT":
                self.ekf_flags = msg.flags
                self.ekf_reports += 1
            elif kind == "HOME_POSITION":
                self.home_ok = True
            elif kind == "SYS_STATUS":
                bit = mavlink.MAV_SYS_STATUS_PREARM_CHECK
                if msg.onboard_control_sensors_present & bit:
                    self.prearm_ok = bool(msg.onboard_control_sensors_health & bit)
                if msg.battery_remaining >= 0:
                    self.battery_percent = float(msg.battery_remaining)
            elif kind == "DISTANCE_SENSOR" and msg.orientation == mavlink.MAV_SENSOR_ROTATION_NONE:
                # forward only (a downward one measures height); centimetres, in its own range or none
                in_range = msg.min_distance <= msg.current_distance <= msg.max_distance
                self.forward_range_m = msg.current_distance / 100.0 if in_range else None
            elif kind == "SYSTEM_TIME":
                self._clock(msg.time_boot_ms)
            elif kind == "STATUSTEXT":
                self.texts.add(f"{_severity(msg.severity)}: {msg.text}")

    def _clock(self, time_boot_ms: int) -> None:
        stamp_s = time_boot_ms * 1e-3
        if not stamp_s <= self.vehicle_time_s:  # the first stamp, or a newer one (never backwards)
            self.vehicle_time_s = stamp_s

    # ------------------------------------------------------------------ for the backend
    @property
    def in_air(self) -> bool:
        if self.landed_state == mavlink.MAV_LANDED_STATE_UNDEFINED:
            return self.armed and self.system_status == mavlink.MAV_STATE_ACTIVE
        return self.landed_state in _IN_AIR_STATES

    @property
    def estimator_ok(self) -> bool:
        flags = self.ekf_flags
        return (flags & EKF_READY_FLAGS) == EKF_READY_FLAGS and not flags & mavlink.EKF_CONST_POS_MODE

    def snapshot(self, timestamp_s: float) -> Telemetry:
        with self.lock:
            return Telemetry(
                position_ned=PositionNed(*self.position),
                velocity_ned=VelocityNed(*self.velocity),
                attitude=Attitude(*self.attitude),
                armed=self.armed,
                in_air=self.in_air,
                flight_mode=flight_mode_of(self.custom_mode),
                timestamp_s=timestamp_s,
                battery_remaining_percent=self.battery_percent,
                forward_range_m=self.forward_range_m,
            )


def _severity(severity: int) -> str:
    names = {0: "EMERGENCY", 1: "ALERT", 2: "CRITICAL", 3: "ERROR", 4: "WARNING", 5: "NOTICE", 6: "INFO"}
    return names.get(severity, "DEBUG")
