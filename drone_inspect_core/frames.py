"""Frame conventions, in one place.

The PyBullet world is ENU (x east, y north, z up) with body axes FLU (forward,
left, up). Everything on the flight interface is NED (north, east, down) with
body axes FRD (forward, right, down), as in MAVLink and MAVSDK. Yaw in NED is
measured from north towards east; yaw in ENU from east towards north, so
yaw_ned = 90° − yaw_enu.
"""

from __future__ import annotations

import math

import numpy as np

_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # its own inverse


def enu_to_ned(v_enu: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """A vector (position, velocity, ...) from ENU to NED."""
    return _ENU_NED @ np.asarray(v_enu, dtype=float)


def ned_to_enu(v_ned: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """A vector from NED to ENU."""
    return _ENU_NED @ np.asarray(v_ned, dtype=float)


def flu_to_frd(v_flu: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """A body vector from FLU to FRD (the same flip both ways)."""
    x, y, z = np.asarray(v_flu, dtype=float)
    return np.array([x, -y, -z])


frd_to_flu = flu_to_frd


def wrap_rad(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def yaw_enu_to_ned_rad(yaw_enu_rad: float) -> float:
    """ENU yaw (from east, counter-clockwise) to NED yaw (from north, clockwise)."""
    return wrap_rad(math.pi / 2.0 - yaw_enu_rad)


yaw_ned_to_enu_rad = yaw_enu_to_ned_rad  # the map is its own inverse


def heading_to_world_ned(forward: float, right: float, yaw_ned_rad: float) -> tuple[float, float]:
    """A horizontal vector in the yaw-only body frame (forward, right) to (north, east)."""
    c, s = math.cos(yaw_ned_rad), math.sin(yaw_ned_rad)
    return c * forward - s * right, s * forward + c * right


def world_ned_to_heading(north: float, east: float, yaw_ned_rad: float) -> tuple[float, float]:
    """A horizontal (north, east) vector to the yaw-only body frame (forward, right)."""
    c, s = math.cos(yaw_ned_rad), math.sin(yaw_ned_rad)
    return c * north + s * east, -s * north + c * east
