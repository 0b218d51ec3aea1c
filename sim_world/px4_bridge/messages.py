"""PX4's simulator MAVLink API, message by message, as PX4 v1.15 reads it (`SimulatorMavlink.cpp`).

- HIL_SENSOR: `time_usec` sets PX4's clock (lockstep); `fields_updated` says which
  groups are new: bits 0-2 accelerometer, 3-5 gyro, 6-8 magnetometer, 9 absolute
  pressure, 10 differential pressure, 11 pressure altitude, 12 temperature (PX4 takes
  a barometer sample only with 9, 11 and 12 together); `id` 0 is the primary IMU,
  the one PX4 steps its clock on.
- HIL_GPS: degE7, mm, cm, cm/s, cdeg; `cog` 65535 when unknown; `yaw` 0 = no heading.
- HIL_STATE_QUATERNION: truth, which PX4 only logs as ground truth.
- HIL_ACTUATOR_CONTROLS from PX4: `controls[0..3]` are the four motors in [0, 1]
  (PWM_MAIN_FUNC1..4 = motors 1..4 of the quad X), all zero while disarmed; `mode`
  carries MAV_MODE_FLAG_SAFETY_ARMED (128); `flags` bit 0 = lockstep.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core import mavlink_frames
from sim_world.physics.quadrotor import GRAVITY_M_S2, QuadrotorParams
from sim_world.px4_bridge.sensors import BaroReading, GpsReading, ImuReading, Truth
from sim_world.sitl.rig import quaternion_wxyz

ACCEL_BITS = 0b111
GYRO_BITS = 0b111 << 3
MAG_BITS = 0b111 << 6
BARO_BITS = (1 << 9) | (1 << 11) | (1 << 12)
ARMED_FLAG = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
LOCKSTEP_FLAG = 1


@dataclass(frozen=True)
class ActuatorCommand:
    """One HIL_ACTUATOR_CONTROLS: PX4's time, whether it is armed, the four motor outputs in [0, 1]."""

    time_usec: int
    armed: bool
    motors: tuple[float, float, float, float]
    lockstep: bool


_ACTUATORS = mavlink.MAVLink_hil_actuator_controls_message
_ACTUATOR_PAYLOAD_BYTES = _ACTUATORS.unpacker.size  # time_usec, flags, controls[16], mode (wire order)


def actuator_command(payload: bytes) -> ActuatorCommand:
    """The HIL_ACTUATOR_CONTROLS whose (CRC-checked) MAVLink 2 payload is `payload`, decoded as pymavlink
    decodes it (trailing zeros, which MAVLink 2 cuts, restored) without building its message object:
    PX4 sends one for every 4 ms tick of the lockstep."""
    if len(payload) < _ACTUATOR_PAYLOAD_BYTES:
        payload = payload + bytes(_ACTUATOR_PAYLOAD_BYTES - len(payload))
    values = _ACTUATORS.unpacker.unpack_from(payload)
    time_usec, flags, mode = values[0], values[1], values[18]
    return ActuatorCommand(
        time_usec=int(time_usec),
        armed=bool(mode & ARMED_FLAG),
        motors=(_unit(values[2]), _unit(values[3]), _unit(values[4]), _unit(values[5])),
        lockstep=bool(flags & LOCKSTEP_FLAG),
    )


def _unit(value: float) -> float:
    """A motor output clamped to [0, 1]; NaN (an output PX4 leaves unset) counts as 0."""
    return 0.0 if not math.isfinite(value) else min(max(value, 0.0), 1.0)


@dataclass(frozen=True)
class RotorMapping:
    """Motor output u ∈ [0, 1] → rotor speed command, as Gazebo's iris: ω = idle + u·(max − idle) when armed.

    A disarmed PX4 sends zeros and the flag says so: the rotors are commanded to stop.
    """

    max_rad_s: float
    idle_rad_s: float = 100.0

    @classmethod
    def for_quad(cls, quad: QuadrotorParams) -> RotorMapping:
        return cls(max_rad_s=quad.max_rotor_speed_rad_s)

    def hover_output(self, quad: QuadrotorParams) -> float:
        """The motor output u at which the four rotors (thrust kf·ω² each) hold `quad`'s weight."""
        hover_rad_s = math.sqrt(quad.mass_kg * GRAVITY_M_S2 / (4.0 * quad.kf))
        return (hover_rad_s - self.idle_rad_s) / (self.max_rad_s - self.idle_rad_s)

    def rotor_speeds(self, command: ActuatorCommand | None) -> list[float]:
        if command is None or not command.armed:
            return [0.0, 0.0, 0.0, 0.0]
        span = self.max_rad_s - self.idle_rad_s
        return [self.idle_rad_s + u * span for u in command.motors]


def px4_airframe_params(quad: QuadrotorParams) -> dict[str, float]:
    """What PX4 must know of the quad it flies beyond its iris airframe's geometry and tuning: the hover
    thrust (MPC_THR_HOVER). The iris's 0.5 left the 1 kg quad (hover at 0.638) on the ground for seconds
    after each takeoff began, until PX4's velocity controller had integrated the difference."""
    return {"MPC_THR_HOVER": round(RotorMapping.for_quad(quad).hover_output(quad), 3)}


_V2_HEADER = struct.Struct("<BBBBBBBHB")  # magic, length, flags, flags, seq, system, component, id (24 bit)
_HIL_SENSOR = mavlink.MAVLink_hil_sensor_message


class HilEncoder:
    """Builds the simulator's messages with one MAVLink 2 sequence counter.

    HIL_SENSOR, sent every 4 ms tick, is packed here byte for byte as pymavlink packs it, without building
    a message object; the others through pymavlink."""

    def __init__(self, system_id: int = 1, component_id: int = 51) -> None:
        self._mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._mav.robust_parsing = True
        self._seq = 0

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) & 0xFF
        return seq

    def pack(self, msg: mavlink.MAVLink_message) -> bytes:
        self._mav.seq = self._next_seq()
        return msg.pack(self._mav)

    def _frame(self, message: type[mavlink.MAVLink_message], payload: bytes) -> bytes:
        """`payload` (the fields in wire order) as one unsigned MAVLink 2 frame of `message`'s id."""
        length = len(payload)
        while length > 1 and payload[length - 1] == 0:  # MAVLink 2 cuts trailing zeros
            length -= 1
        msg_id, mav = message.id, self._mav
        header = _V2_HEADER.pack(
            mavlink.PROTOCOL_MARKER_V2, length, 0, 0, self._next_seq(), mav.srcSystem, mav.srcComponent,
            msg_id & 0xFFFF, msg_id >> 16,
        )  # fmt: skip
        frame = header + payload[:length]
        return frame + struct.pack("<H", mavlink_frames.crc(frame[1:], message.crc_extra))

    def heartbeat(self) -> bytes:
        return self.pack(
            mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_GENERIC, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
            )
        )

    def hil_sensor(
        self, time_usec: int, imu: ImuReading, mag: np.ndarray | None, baro: BaroReading | None
    ) -> bytes:
        fields = ACCEL_BITS | GYRO_BITS
        mx = my = mz = 0.0
        pressure = altitude = temperature = 0.0
        if mag is not None:
            fields |= MAG_BITS
            mx, my, mz = (float(v) for v in mag)
        if baro is not None:
            fields |= BARO_BITS
            pressure, altitude, temperature = baro.pressure_hpa, baro.pressure_altitude_m, baro.temperature_c
        ax, ay, az = imu.accel_frd_m_s2.tolist()
        gx, gy, gz = imu.gyro_frd_rad_s.tolist()
        payload = _HIL_SENSOR.unpacker.pack(
            time_usec, ax, ay, az, gx, gy, gz, mx, my, mz, pressure, 0.0, altitude, temperature, fields, 0
        )
        return self._frame(_HIL_SENSOR, payload)

    def hil_gps(self, time_usec: int, gps: GpsReading) -> bytes:
        vn, ve, vd = (float(v) for v in gps.velocity_ned_m_s)
        ground_speed = math.hypot(vn, ve)
        cog = 65535 if ground_speed < 0.05 else round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100) % 36000
        return self.pack(
            mavlink.MAVLink_hil_gps_message(
                time_usec,
                3,  # 3D fix
                round(gps.latitude_deg * 1e7),
                round(gps.longitude_deg * 1e7),
                round(gps.altitude_amsl_m * 1000.0),
                round(gps.eph_m * 100.0),
                round(gps.epv_m * 100.0),
                round(ground_speed * 100.0),
                round(vn * 100.0),
                round(ve * 100.0),
                round(vd * 100.0),
                cog,
                gps.satellites,
                0,
                0,
            )
        )

    def hil_state_quaternion(
        self, time_usec: int, truth: Truth, global_position: tuple[float, float, float]
    ) -> bytes:
        lat, lon, alt = global_position
        vn, ve, vd = (float(v) for v in truth.velocity_ned_m_s)
        body_accel = truth.rotation_ned_frd.T @ (truth.acceleration_ned_m_s2 - np.array([0.0, 0.0, 9.80665]))
        p, q, r = (float(v) for v in truth.rates_frd_rad_s)
        speed_cm_s = round(math.sqrt(vn * vn + ve * ve + vd * vd) * 100.0)
        return self.pack(
            mavlink.MAVLink_hil_state_quaternion_message(
                time_usec,
                quaternion_wxyz(truth.rotation_ned_frd),
                p,
                q,
                r,
                round(lat * 1e7),
                round(lon * 1e7),
                round(alt * 1000.0),
                round(vn * 100.0),
                round(ve * 100.0),
                round(vd * 100.0),
                speed_cm_s,
                speed_cm_s,
                *(max(-32768, min(32767, round(a / 9.80665 * 1000.0))) for a in body_accel),
            )
        )
