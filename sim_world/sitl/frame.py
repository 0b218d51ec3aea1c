"""Where an autopilot kept warm between missions believes the world is: `AutopilotFrame`.

A fresh autopilot boots with its frame on the world's: NED from the drone's resting point, its clock from
the world's start. One kept running while its bridge builds the next mission's world (a new scene, the
drone landed below a new start) must see no jump: a drone that vanished from where it landed and rested
elsewhere, turned, with its clock set back, would upset its estimator. So the bridge shows it the new
world through a rigid turn about the vertical, a shift and a clock offset, chosen so that the new
world's start is exactly where and when the autopilot last saw the drone (`continuing`). Physics, the
camera and the judging truth stay in the new world's own frame, so the mission flies the world a fresh
simulator builds; a rotor command, in the body frame, means the same in both.

Everything an autopilot senses turns with the frame: position, velocity and acceleration (NED),
attitude; body rates and the specific force of the IMU do not change (the turn is about gravity's axis).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from sim_world.sitl.imu import Truth


def _yaw_ned_rad(rotation_ned_frd: np.ndarray) -> float:
    """The heading of a body-to-NED rotation (from north, clockwise seen from above)."""
    return math.atan2(float(rotation_ned_frd[1, 0]), float(rotation_ned_frd[0, 0]))


def _turn(yaw_rad: float) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class AutopilotFrame:
    """The autopilot's frame: the world's NED turned by `yaw_rad` about down, then shifted by
    `offset_ned_m`; its clock the world's plus `time_offset_s`. The identity for a fresh autopilot."""

    yaw_rad: float = 0.0
    offset_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    time_offset_s: float = 0.0

    @cached_property
    def turn(self) -> np.ndarray:
        return _turn(self.yaw_rad)

    @cached_property
    def identity(self) -> bool:
        return self.yaw_rad == 0.0 and not self.offset_ned_m.any() and self.time_offset_s == 0.0

    def apply(self, truth: Truth) -> Truth:
        """`truth` (in the world's frame) as the autopilot is to sense it (a bridge's every physics frame)."""
        if self.identity:
            return truth
        turn = self.turn
        return Truth(
            time_s=truth.time_s + self.time_offset_s,
            position_ned_m=turn @ truth.position_ned_m + self.offset_ned_m,
            velocity_ned_m_s=turn @ truth.velocity_ned_m_s,
            acceleration_ned_m_s2=turn @ truth.acceleration_ned_m_s2,
            rotation_ned_frd=turn @ truth.rotation_ned_frd,
            rates_frd_rad_s=truth.rates_frd_rad_s,
        )

    def time_s(self, world_time_s: float) -> float:
        """The autopilot's clock at the world's `world_time_s`."""
        return world_time_s + self.time_offset_s

    @classmethod
    def continuing(cls, last_seen: Truth, start: Truth, next_time_s: float) -> AutopilotFrame:
        """The frame in which the new world's `start` (its truth, in its own frame) is where and when the
        autopilot last saw the drone (`last_seen`, in the autopilot's frame): same position and heading,
        its clock at `next_time_s` (the autopilot's, the next tick after the last one it had)."""
        yaw = _yaw_ned_rad(last_seen.rotation_ned_frd) - _yaw_ned_rad(start.rotation_ned_frd)
        offset = last_seen.position_ned_m - _turn(yaw) @ start.position_ned_m
        return cls(yaw, offset, next_time_s - start.time_s)
