"""`VehicleLimits`: what a vehicle we start holds by itself, whatever a client on its link asks.

The controller clips its own commands (`flight.safety.SafetyLimits`), but a link can carry other
senders, and a controller can have a bug: the vehicle must keep its own limits too. Whoever starts a
vehicle sets them (a mission kit from the mission's safety limits, `dronectl sim-vehicle` from its
options); over MAVLink a client may tighten a limit (PX4's parameters), never loosen it, and a limit
of 0 stops that motion (it never means "no limit").

Each autopilot gets them its own way: the sim-vehicle enforces them in its commander and bounds its
parameters with them (`sim_world.vehicle`); PX4 as parameters at boot (`px4_params`); ArduPilot can
map the same fields onto its own (WPNAV_SPEED, FENCE_RADIUS, FENCE_ALT_MAX, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PX4_MAX_HORIZONTAL_SPEED_M_S = 12.0
"""PX4's MPC_XY_VEL_MAX default; the most a vehicle we start will fly unless told otherwise."""


def _check(owner: object, name: str, low: float, high: float) -> None:
    value = getattr(owner, name)
    if not (isinstance(value, int | float) and math.isfinite(value) and low <= value <= high):
        raise ValueError(f"{type(owner).__name__}.{name} must be in [{low:g}, {high:g}], got {value!r}")


@dataclass(frozen=True)
class VehicleLimits:
    """Speed limits and a fence around home (a cylinder: radius and height), held by the vehicle itself."""

    max_horizontal_speed_m_s: float = PX4_MAX_HORIZONTAL_SPEED_M_S
    max_up_m_s: float = 3.0
    max_down_m_s: float = 1.5
    max_yaw_rate_deg_s: float = 45.0
    fence_radius_m: float | None = None
    """Horizontal distance from home the vehicle will not fly past (None: no fence)."""
    fence_max_altitude_m: float | None = None
    """Height above home the vehicle will not climb past (None: no ceiling)."""

    def __post_init__(self) -> None:
        _check(self, "max_horizontal_speed_m_s", 0.0, 20.0)
        _check(self, "max_up_m_s", 0.0, 8.0)
        _check(self, "max_down_m_s", 0.0, 4.0)
        _check(self, "max_yaw_rate_deg_s", 0.0, 360.0)
        if self.fence_radius_m is not None:
            _check(self, "fence_radius_m", 1.0, 10_000.0)
        if self.fence_max_altitude_m is not None:
            _check(self, "fence_max_altitude_m", 1.0, 10_000.0)

    @property
    def has_fence(self) -> bool:
        return self.fence_radius_m is not None or self.fence_max_altitude_m is not None

    @classmethod
    def around(
        cls,
        horizontal_speed_m_s: float,
        vertical_speed_m_s: float,
        yaw_rate_deg_s: float,
        box_half_widths_m: tuple[float, float] | None,
        box_height_m: float | None,
        margin: float = 1.5,
    ) -> VehicleLimits:
        """Limits a little wider than a controller's own (`margin` × its speeds; a fence around its box),
        so the vehicle never cuts short what the controller may do, and stops what it may not."""
        radius = None if box_half_widths_m is None else math.hypot(*box_half_widths_m) + 1.0
        return cls(
            max_horizontal_speed_m_s=min(20.0, horizontal_speed_m_s * margin),
            max_up_m_s=min(8.0, vertical_speed_m_s * margin),
            max_down_m_s=min(4.0, vertical_speed_m_s * margin),
            max_yaw_rate_deg_s=min(360.0, yaw_rate_deg_s * margin),
            fence_radius_m=radius,
            fence_max_altitude_m=None if box_height_m is None else box_height_m + 1.0,
        )

    def px4_params(self) -> dict[str, float]:
        """The horizontal limits as PX4 parameters, set at boot. The vertical ones are left to PX4: its
        takeoff and landing speeds (MPC_TKO_SPEED, MPC_LAND_SPEED) are bounded by them."""
        params = {
            "MPC_XY_VEL_MAX": self.max_horizontal_speed_m_s,
            "MPC_YAWRAUTO_MAX": self.max_yaw_rate_deg_s,
        }
        if self.fence_radius_m is not None:
            params["GF_MAX_HOR_DIST"] = self.fence_radius_m
        if self.fence_max_altitude_m is not None:
            params["GF_MAX_VER_DIST"] = self.fence_max_altitude_m
        return params
