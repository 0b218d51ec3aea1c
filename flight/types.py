"""Value types on the flight interface: NED world frame, FRD body frame, units in the names.

They mirror MAVSDK's (`VelocityBodyYawspeed`, `PositionNed`, ...) so that a
backend converts field by field, and carry no behaviour beyond small helpers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Protocol


@dataclass(frozen=True)
class VelocityBody:
    """A velocity command in the yaw-only body frame (FRD): forward, right, down, yaw rate."""

    forward_m_s: float = 0.0
    right_m_s: float = 0.0
    down_m_s: float = 0.0
    yawspeed_deg_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("forward_m_s", "right_m_s", "down_m_s", "yawspeed_deg_s"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"VelocityBody.{name} must be finite, got {getattr(self, name)!r}")

    @property
    def horizontal_m_s(self) -> float:
        return math.hypot(self.forward_m_s, self.right_m_s)

    def is_zero(self) -> bool:
        return self == ZERO_VELOCITY


ZERO_VELOCITY = VelocityBody()


@dataclass(frozen=True)
class PositionNed:
    """A local position relative to the vehicle's origin (usually home), NED metres."""

    north_m: float
    east_m: float
    down_m: float

    def __sub__(self, other: PositionNed) -> PositionNed:
        return PositionNed(
            self.north_m - other.north_m, self.east_m - other.east_m, self.down_m - other.down_m
        )

    @property
    def horizontal_m(self) -> float:
        return math.hypot(self.north_m, self.east_m)


@dataclass(frozen=True)
class VelocityNed:
    """A velocity in the local NED frame."""

    north_m_s: float
    east_m_s: float
    down_m_s: float

    @property
    def horizontal_m_s(self) -> float:
        return math.hypot(self.north_m_s, self.east_m_s)

    @property
    def speed_m_s(self) -> float:
        return math.sqrt(self.north_m_s**2 + self.east_m_s**2 + self.down_m_s**2)


@dataclass(frozen=True)
class Attitude:
    """Euler angles (3-2-1), NED yaw: 0° = north, clockwise positive."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


class FlightMode(Enum):
    """The flight modes a client needs to tell apart (the PX4 names MAVSDK reports)."""

    UNKNOWN = "unknown"
    READY = "ready"
    TAKEOFF = "takeoff"
    HOLD = "hold"
    OFFBOARD = "offboard"
    LAND = "land"
    POSCTL = "posctl"
    ALTCTL = "altctl"
    MANUAL = "manual"
    RETURN_TO_LAUNCH = "return_to_launch"
    MISSION = "mission"
    OTHER = "other"


@dataclass(frozen=True)
class Telemetry:
    """One snapshot of the vehicle's state. `timestamp_s` is on the vehicle's clock (`Vehicle.time_s()`)."""

    position_ned: PositionNed
    velocity_ned: VelocityNed
    attitude: Attitude
    armed: bool
    in_air: bool
    flight_mode: FlightMode
    timestamp_s: float
    battery_remaining_percent: float | None = None
    forward_range_m: float | None = None
    """A forward rangefinder's latest reading (MAVLink DISTANCE_SENSOR, orientation forward), metres;
    None without one, or when it sees nothing within its range."""


@dataclass(frozen=True)
class Displacement:
    """A displacement expressed both in NED and in the yaw-only body frame of the start pose."""

    north_m: float
    east_m: float
    down_m: float
    forward_m: float
    right_m: float

    @property
    def horizontal_m(self) -> float:
        return math.hypot(self.north_m, self.east_m)


class Closable(Protocol):
    """Something a vehicle owns and closes last (the relay in front of its link)."""

    def close(self) -> None: ...
