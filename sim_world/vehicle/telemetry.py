"""Telemetry: the messages a PX4 vehicle streams, built from a snapshot, and their rates.

MAVSDK reads armed state and flight mode from HEARTBEAT only, health from SYS_STATUS
`onboard_control_sensors_health` (gyro/accel/mag → calibration, GPS → position OK,
PREARM_CHECK → armable), in-air from EXTENDED_SYS_STATE, position/velocity from
LOCAL_POSITION_NED and attitude from ATTITUDE: those are built here with the fields
PX4 fills. Rates are kept in wall-clock time (a client's link timeouts are wall
time even when the simulation runs N× real time) and follow SET_MESSAGE_INTERVAL.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.state_streams import HEARTBEAT_HZ, LANDED_STATE_HZ
from sim_world.vehicle.model import Kinematics
from sim_world.vehicle.px4_modes import Px4MainMode, Px4Mode

EARTH_RADIUS_M = 6_378_137.0
PX4_VERSION = (1, 16, 0)

M = mavlink
DEFAULT_RATES_HZ: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: HEARTBEAT_HZ,
    M.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: LANDED_STATE_HZ,
    M.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    M.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,  # PX4's rate on its onboard link
    M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: 0.0,  # on request only
}
"""What the sim-vehicle streams until a client asks otherwise (SET_MESSAGE_INTERVAL): what MAVSDK reads
(see the module doc), at PX4's onboard rates or the state rates of `drone_inspect_core.state_streams`.
PX4's link we start streams the same (`sim_world.px4_bridge.px4_process.API_LINK_STREAMS_HZ`)."""
RANGEFINDER_MIN_CM, RANGEFINDER_MAX_CM = 10, 1200
"""The forward rangefinder's limits as DISTANCE_SENSOR reports them (`sim_world.physics.rangefinder`)."""

_SENSORS = (
    M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | M.MAV_SYS_STATUS_SENSOR_3D_MAG
    | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_GPS
    | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | M.MAV_SYS_STATUS_AHRS
    | M.MAV_SYS_STATUS_SENSOR_BATTERY
    | M.MAV_SYS_STATUS_GEOFENCE  # present, enabled and healthy (no breach), as PX4 reports it
)
_CAPABILITIES = (
    M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
)


@dataclass(frozen=True)
class HomePoint:
    """The fixed geodetic origin of the local NED frame (default: PX4 SITL's Zurich home)."""

    latitude_deg: float = 47.397742
    longitude_deg: float = 8.545594
    altitude_amsl_m: float = 488.0

    def to_global(self, north_m: float, east_m: float, down_m: float) -> tuple[float, float, float]:
        """Local NED metres to (lat_deg, lon_deg, alt_amsl_m), flat-earth (fine over a few km)."""
        lat = self.latitude_deg + math.degrees(north_m / EARTH_RADIUS_M)
        lon = self.longitude_deg + math.degrees(
            east_m / (EARTH_RADIUS_M * math.cos(math.radians(self.latitude_deg)))
        )
        return lat, lon, self.altitude_amsl_m - down_m


@dataclass(frozen=True)
class VehicleSnapshot:
    """Everything the message builders read, taken once per loop tick."""

    time_boot_ms: int
    kinematics: Kinematics
    armed: bool
    mode: Px4Mode
    system_status: int
    landed_state: int
    prearm_ok: bool
    battery_remaining: float  # 0..1
    battery_voltage_v: float
    battery_current_a: float
    battery_consumed_mah: float


class TelemetryBuilder:
    """Builds one message of a streamed type from a snapshot."""

    def __init__(self, home: HomePoint, uid: int):
        self.home = home
        self.uid = uid
        self._builders: dict[int, Callable[[VehicleSnapshot], mavlink.MAVLink_message]] = {
            M.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            M.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            M.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            M.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            M.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            M.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            M.MAVLINK_MSG_ID_DISTANCE_SENSOR: self.distance_sensor,
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
        }

    def supports(self, msg_id: int) -> bool:
        return msg_id in self._builders

    def build(self, msg_id: int, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        return self._builders[msg_id](snap)

    def heartbeat(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if snap.mode.main in (Px4MainMode.AUTO, Px4MainMode.OFFBOARD, Px4MainMode.POSCTL):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if snap.mode.main == Px4MainMode.AUTO:
            base |= M.MAV_MODE_FLAG_AUTO_ENABLED
        if snap.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        return M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base, snap.mode.custom_mode, snap.system_status, 3
        )

    def sys_status(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        present = _SENSORS | M.MAV_SYS_STATUS_PREARM_CHECK
        health = _SENSORS | (M.MAV_SYS_STATUS_PREARM_CHECK if snap.prearm_ok else 0)
        return M.MAVLink_sys_status_message(
            present, present, health, 150, round(snap.battery_voltage_v * 1000),
            round(snap.battery_current_a * 100), round(snap.battery_remaining * 100), 0, 0, 0, 0, 0, 0,
        )  # fmt: skip

    def extended_sys_state(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, snap.landed_state)

    def attitude(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        k = snap.kinematics
        p, q, r = (float(x) for x in k.rates_frd_rad_s)
        return M.MAVLink_attitude_message(snap.time_boot_ms, k.roll_rad, k.pitch_rad, k.yaw_rad, p, q, r)

    def local_position_ned(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        k = snap.kinematics
        x, y, z = (float(v) for v in k.position_ned_m)
        vx, vy, vz = (float(v) for v in k.velocity_ned_m_s)
        return M.MAVLink_local_position_ned_message(snap.time_boot_ms, x, y, z, vx, vy, vz)

    def global_position_int(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        k = snap.kinematics
        lat, lon, alt = self.home.to_global(*(float(v) for v in k.position_ned_m))
        vx, vy, vz = (_clip_i16(round(float(v) * 100)) for v in k.velocity_ned_m_s)
        heading_cdeg = round(math.degrees(k.yaw_rad) * 100) % 36000
        return M.MAVLink_global_position_int_message(
            snap.time_boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
            round(-float(k.position_ned_m[2]) * 1000), vx, vy, vz, heading_cdeg,
        )  # fmt: skip

    def gps_raw_int(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        k = snap.kinematics
        lat, lon, alt = self.home.to_global(*(float(v) for v in k.position_ned_m))
        vn, ve = float(k.velocity_ned_m_s[0]), float(k.velocity_ned_m_s[1])
        cog_cdeg = round(math.degrees(math.atan2(ve, vn)) * 100) % 36000
        return M.MAVLink_gps_raw_int_message(
            snap.time_boot_ms * 1000, M.GPS_FIX_TYPE_3D_FIX, round(lat * 1e7), round(lon * 1e7),
            round(alt * 1000), 70, 110, round(math.hypot(vn, ve) * 100), cog_cdeg, 14,
        )  # fmt: skip

    def battery_status(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        voltages = [min(65534, round(snap.battery_voltage_v * 1000))] + [65535] * 9
        return M.MAVLink_battery_status_message(
            0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, voltages,
            round(snap.battery_current_a * 100), round(snap.battery_consumed_mah), -1,
            round(snap.battery_remaining * 100),
        )  # fmt: skip

    def home_position(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        h = self.home
        return M.MAVLink_home_position_message(
            round(h.latitude_deg * 1e7), round(h.longitude_deg * 1e7), round(h.altitude_amsl_m * 1000),
            0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, snap.time_boot_ms * 1000,
        )  # fmt: skip

    def distance_sensor(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        """The forward rangefinder (orientation ROTATION_NONE = forward); beyond its maximum when it
        sees nothing, as a real one reports no return."""
        return distance_sensor_message(snap.time_boot_ms, snap.kinematics.forward_range_m)

    def autopilot_version(self, snap: VehicleSnapshot) -> mavlink.MAVLink_message:
        major, minor, patch = PX4_VERSION
        sw = major << 24 | minor << 16 | patch << 8 | M.FIRMWARE_VERSION_TYPE_OFFICIAL
        return M.MAVLink_autopilot_version_message(
            _CAPABILITIES, sw, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, self.uid,
        )  # fmt: skip


def distance_sensor_message(time_boot_ms: int, range_m: float | None) -> mavlink.MAVLink_message:
    """DISTANCE_SENSOR of a forward laser rangefinder reading `range_m` (None: no return, sent as one
    centimetre beyond the maximum with signal quality 1, the lowest)."""
    if range_m is None or not math.isfinite(range_m):
        current, quality = RANGEFINDER_MAX_CM + 1, 1
    else:
        current, quality = min(max(round(range_m * 100), RANGEFINDER_MIN_CM), RANGEFINDER_MAX_CM), 100
    return M.MAVLink_distance_sensor_message(
        time_boot_ms, RANGEFINDER_MIN_CM, RANGEFINDER_MAX_CM, current, M.MAV_DISTANCE_SENSOR_LASER, 0,
        M.MAV_SENSOR_ROTATION_NONE, 1, signal_quality=quality,
    )  # fmt: skip


def _clip_i16(value: int) -> int:
    return max(-32768, min(32767, value))


class MessageScheduler:
    """Per-message send intervals (wall-clock), changed by SET_MESSAGE_INTERVAL."""

    def __init__(self, default_rates_hz: Mapping[int, float], now_s: float):
        self._defaults = dict(default_rates_hz)
        self._interval_s: dict[int, float | None] = {m: _interval(hz) for m, hz in self._defaults.items()}
        self._next_s: dict[int, float] = {m: now_s for m in self._defaults}

    def supports(self, msg_id: int) -> bool:
        return msg_id in self._defaults

    def interval_us(self, msg_id: int) -> int:
        """For MESSAGE_INTERVAL: µs, -1 when disabled, 0 when the message is not available."""
        if msg_id not in self._defaults:
            return 0
        interval = self._interval_s[msg_id]
        return -1 if interval is None else round(interval * 1e6)

    def set_interval(self, msg_id: int, interval_us: float, now_s: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL semantics (-1 off, 0 default, else µs); False if unknown."""
        if msg_id not in self._defaults or not math.isfinite(interval_us):
            return False
        if interval_us < 0:
            self._interval_s[msg_id] = None
        elif interval_us == 0:
            self._interval_s[msg_id] = _interval(self._defaults[msg_id])
        else:
            self._interval_s[msg_id] = max(interval_us * 1e-6, 0.001)  # at most 1 kHz
        self._next_s[msg_id] = now_s
        return True

    def due(self, now_s: float) -> list[int]:
        """The messages to send now; each is rescheduled one interval later."""
        out = []
        for msg_id, interval in self._interval_s.items():
            if interval is None or now_s < self._next_s[msg_id]:
                continue
            out.append(msg_id)
            nxt = self._next_s[msg_id] + interval
            # After a stall, restart the rhythm instead of sending a burst of late messages.
            self._next_s[msg_id] = nxt if nxt > now_s - interval else now_s + interval
        return out

    def next_due_s(self) -> float:
        """The earliest time a message is due (inf when all are off)."""
        times = [self._next_s[m] for m, i in self._interval_s.items() if i is not None]
        return min(times, default=math.inf)


def _interval(rate_hz: float) -> float | None:
    return 1.0 / rate_hz if rate_hz > 0 else None
