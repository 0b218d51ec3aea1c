"""SET_POSITION_TARGET_LOCAL_NED as PX4 reads it, reduced to what the sim can fly.

PX4 accepts MAV_FRAME_LOCAL_NED (1) and MAV_FRAME_BODY_NED (8) and refuses other
frames with a "coordinate frame unsupported" STATUSTEXT. The sim's autopilot flies
velocities, so a setpoint must carry a velocity (type_mask bits 3-5 clear: MAVSDK's
`set_velocity_body` sends type_mask 1479); fields it ignores count as zero. The yaw
may come as a rate (bit 11 clear) or an absolute heading (bit 10 clear).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from pymavlink.dialects.v20 import common as mavlink

IGNORE_POSITION = 0b111  # bits 0-2
IGNORE_VELOCITY = 0b111 << 3
IGNORE_ACCELERATION = 0b111 << 6
IGNORE_YAW = 1 << 10
IGNORE_YAW_RATE = 1 << 11
VELOCITY_YAWRATE_MASK = IGNORE_POSITION | IGNORE_ACCELERATION | IGNORE_YAW  # 1479, as MAVSDK sends


class SetpointFrame(Enum):
    LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
    BODY_NED = mavlink.MAV_FRAME_BODY_NED


class SetpointRejected(ValueError):
    """A setpoint PX4 (or the sim) refuses; the message goes out as a STATUSTEXT."""


@dataclass(frozen=True)
class VelocitySetpoint:
    """A velocity setpoint: (forward, right, down) for BODY_NED, (north, east, down) for LOCAL_NED."""

    frame: SetpointFrame
    velocity_m_s: tuple[float, float, float]
    yawspeed_deg_s: float = 0.0
    yaw_deg: float | None = None  # an absolute NED heading instead of a rate
    received_s: float = 0.0

    def limited(
        self, max_xy_m_s: float, max_up_m_s: float, max_down_m_s: float, max_yaw_deg_s: float
    ) -> VelocitySetpoint:
        """The same setpoint with PX4's speed limits (MPC_*_VEL_MAX, MPC_YAWRAUTO_MAX) applied; a limit
        of 0 stops that motion (never "no limit")."""
        a, b, down = self.velocity_m_s
        xy = math.hypot(a, b)
        if xy > max_xy_m_s:
            a, b = a * max_xy_m_s / xy, b * max_xy_m_s / xy
        down = min(max(down, -max_up_m_s), max_down_m_s)
        yawspeed = min(max(self.yawspeed_deg_s, -max_yaw_deg_s), max_yaw_deg_s)
        return VelocitySetpoint(self.frame, (a, b, down), yawspeed, self.yaw_deg, self.received_s)


def decode_setpoint(
    msg: mavlink.MAVLink_set_position_target_local_ned_message, now_s: float
) -> VelocitySetpoint:
    """A SET_POSITION_TARGET_LOCAL_NED as a `VelocitySetpoint`, or SetpointRejected saying why."""
    try:
        frame = SetpointFrame(msg.coordinate_frame)
    except ValueError:
        raise SetpointRejected(
            f"Offboard: coordinate frame {msg.coordinate_frame} unsupported (use LOCAL_NED 1 or BODY_NED 8)"
        ) from None
    mask = msg.type_mask
    if mask & IGNORE_VELOCITY == IGNORE_VELOCITY:
        raise SetpointRejected("Offboard: only velocity setpoints are supported by the simulated vehicle")
    if mask & IGNORE_POSITION != IGNORE_POSITION:
        raise SetpointRejected("Offboard: position setpoints unsupported by the simulated vehicle")
    values = (msg.vx, msg.vy, msg.vz)
    velocity = tuple(0.0 if mask & (1 << (3 + i)) else float(v) for i, v in enumerate(values))
    if not all(math.isfinite(v) for v in velocity):
        raise SetpointRejected("Offboard: velocity setpoint is not finite")
    yawspeed_deg_s = 0.0
    yaw_deg: float | None = None
    if not mask & IGNORE_YAW_RATE and math.isfinite(msg.yaw_rate):
        yawspeed_deg_s = math.degrees(msg.yaw_rate)
    elif not mask & IGNORE_YAW and math.isfinite(msg.yaw):
        yaw_deg = math.degrees(msg.yaw)
    return VelocitySetpoint(frame, velocity, yawspeed_deg_s, yaw_deg, now_s)  # type: ignore[arg-type]
