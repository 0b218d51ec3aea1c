"""What the MAVLink layer needs from a simulated airframe.

`VehicleModel` is the seam between the protocol (commander, telemetry, commands)
and the physics: `world_model.WorldVehicleModel` implements it over the PyBullet
`World` and its `Autopilot`; unit tests implement it with a small kinematic fake.
Everything crossing this seam is already in MAVLink's frames (NED, body FRD).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class ModelRefused(RuntimeError):
    """The airframe's autopilot refused a transition (e.g. takeoff while disarmed)."""


@dataclass(frozen=True)
class Kinematics:
    """The airframe's true state in MAVLink's frames, relative to the home point."""

    time_s: float
    position_ned_m: np.ndarray  # (3,) north, east, down from home
    velocity_ned_m_s: np.ndarray  # (3,)
    roll_rad: float
    pitch_rad: float
    yaw_rad: float  # NED yaw: from north, clockwise
    rates_frd_rad_s: np.ndarray  # (3,) body roll, pitch, yaw rates
    forward_range_m: float | None = None
    """The forward rangefinder's reading (None: nothing in range, or an airframe without one)."""


@dataclass(frozen=True)
class AutopilotStatus:
    """The low-level autopilot's state, as the commander needs it."""

    armed: bool
    landed: bool
    taking_off: bool  # climbing to a takeoff altitude, not yet there
    landing: bool  # descending in a land, not yet on the ground


class VehicleModel(Protocol):
    """A simulated airframe with its low-level autopilot (velocity control, takeoff, land)."""

    @property
    def physics_hz(self) -> float:
        """Physics steps per simulated second."""
        ...

    @property
    def time_s(self) -> float:
        """Simulated time since start."""
        ...

    def step(self, n: int) -> None:
        """Advance the physics by n steps."""
        ...

    def kinematics(self) -> Kinematics: ...

    def status(self) -> AutopilotStatus: ...

    def arm(self) -> None:
        """Arm; raises ModelRefused when the autopilot will not."""
        ...

    def disarm(self, force: bool) -> None: ...

    def takeoff(self, altitude_m: float) -> None:
        """Climb to `altitude_m` above home, then hold there."""
        ...

    def hold(self) -> None:
        """Hold the current position (zero velocity)."""
        ...

    def land(self) -> None: ...

    def set_velocity_body(
        self, forward_m_s: float, right_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None: ...

    def set_velocity_ned(
        self, north_m_s: float, east_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None: ...
