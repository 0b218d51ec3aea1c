"""The sim-vehicle's own limits (`VehicleLimits`), held whatever a client asks.

- Speeds: a setpoint is flown at most at the smaller of the vehicle's limit and PX4's parameter
  (MPC_*_VEL_MAX, MPC_YAWRAUTO_MAX, which cannot be set past the limit); 0 stops.
- The fence, a cylinder around home and a ceiling: the part of a velocity that would carry the drone
  past it within `FENCE_LOOKAHEAD_S` is dropped (outward along the radius, upward at the ceiling);
  motion along the fence or back inside is kept.

The commander applies both to every setpoint, every loop turn.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from drone_inspect_core.vehicle_limits import VehicleLimits
from sim_world.vehicle.params import ParameterStore

FENCE_LOOKAHEAD_S = 0.5
"""Outward motion stops this long before it would reach the fence."""


def speed_limits(params: ParameterStore, limits: VehicleLimits) -> tuple[float, float, float, float]:
    """(horizontal, up, down m/s, yaw rate deg/s) a setpoint is flown at most at."""
    return (
        min(params.get("MPC_XY_VEL_MAX"), limits.max_horizontal_speed_m_s),
        min(params.get("MPC_Z_VEL_MAX_UP"), limits.max_up_m_s),
        min(params.get("MPC_Z_VEL_MAX_DN"), limits.max_down_m_s),
        min(params.get("MPC_YAWRAUTO_MAX"), limits.max_yaw_rate_deg_s),
    )


def fenced_velocity(
    limits: VehicleLimits, position_ned_m: Sequence[float], velocity_ned_m_s: tuple[float, float, float]
) -> tuple[float, float, float] | None:
    """The NED velocity without what would carry the drone past the fence; None when nothing had to be
    dropped (or there is no fence)."""
    if not limits.has_fence:
        return None
    radius, ceiling = limits.fence_radius_m, limits.fence_max_altitude_m
    n, e, d = (float(v) for v in position_ned_m)
    north, east, down = velocity_ned_m_s
    stopped = False
    r = math.hypot(n, e)
    outward = (north * n + east * e) / r if r > 1e-6 else 0.0
    if radius is not None and outward > 0.0 and r + outward * FENCE_LOOKAHEAD_S >= radius:
        north, east = north - outward * n / r, east - outward * e / r
        stopped = True
    if ceiling is not None and down < 0.0 and -d - down * FENCE_LOOKAHEAD_S >= ceiling:
        down = 0.0
        stopped = True
    return (north, east, down) if stopped else None
