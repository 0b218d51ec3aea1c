"""A kinematic stand-in for the PyBullet airframe, for unit tests of the MAVLink layer only.

`FakeVehicleModel` implements `sim_world.vehicle.model.VehicleModel` with a point
mass whose velocity follows its setpoint with a first-order lag; its modes and
refusals mirror `sim_world.physics.autopilot.Autopilot` (hold refused idle on the ground,
velocity accepted armed on the ground but flown only once it climbs, takeoff refused
while disarmed, disarm refused in the air unless forced).
"""

from __future__ import annotations

import math

import numpy as np

from drone_inspect_core.frames import heading_to_world_ned
from sim_world.vehicle.model import AutopilotStatus, Kinematics, ModelRefused


class FakeVehicleModel:
    """Point-mass airframe; `calls` records every autopilot command for assertions."""

    CLIMB_M_S = 1.0
    LAND_M_S = 0.7
    TAU_S = 0.15
    LIFTOFF_CLIMB_M_S = 0.3  # as AutopilotParams.takeoff_trigger_speed_m_s

    def __init__(self, physics_hz: float = 100.0):
        self._hz = physics_hz
        self._t = 0.0
        self.position = np.zeros(3)  # NED from home
        self.velocity = np.zeros(3)
        self.yaw_rad = 0.0
        self.phase = "disarmed"  # disarmed, idle, takeoff, hold, velocity, land
        self._target = np.zeros(3)
        self._command = (np.zeros(3), False, 0.0)  # velocity, body frame?, yawspeed deg/s
        self.calls: list[tuple] = []

    @property
    def physics_hz(self) -> float:
        return self._hz

    @property
    def time_s(self) -> float:
        return self._t

    def step(self, n: int) -> None:
        dt = 1.0 / self._hz
        for _ in range(n):
            self._step(dt)
            self._t += dt

    def _step(self, dt: float) -> None:
        desired = np.zeros(3)
        if self.phase == "takeoff":
            if self.position[2] <= self._target[2] + 0.02:
                self.phase = "hold"
                self._target = self.position.copy()
            desired[2] = -self.CLIMB_M_S
        elif self.phase == "hold":
            desired = 1.0 * (self._target - self.position)
        elif self.phase == "velocity":
            v, body, yawspeed = self._command
            desired = v.copy()
            if self._velocity_on_ground() and desired[2] > -self.LIFTOFF_CLIMB_M_S:
                self.velocity[:] = 0.0  # stays landed at idle until the setpoint climbs
                return
            if body:
                desired[0], desired[1] = heading_to_world_ned(v[0], v[1], self.yaw_rad)
            self.yaw_rad += math.radians(yawspeed) * dt
        elif self.phase == "land":
            desired[2] = self.LAND_M_S
        if self.phase in ("disarmed", "idle"):
            self.velocity[:] = 0.0
            return
        self.velocity += (desired - self.velocity) * min(1.0, dt / self.TAU_S)
        self.position += self.velocity * dt
        if self.position[2] >= 0.0 and self.phase in ("land", "velocity", "hold") and self.velocity[2] >= 0:
            self.position[2] = 0.0
            if self.phase == "land":
                self.phase = "idle"
                self.velocity[:] = 0.0

    def kinematics(self) -> Kinematics:
        return Kinematics(
            self._t, self.position.copy(), self.velocity.copy(), 0.0, 0.0, self.yaw_rad, np.zeros(3)
        )

    def _velocity_on_ground(self) -> bool:
        return self.phase == "velocity" and self.position[2] >= 0.0

    def status(self) -> AutopilotStatus:
        return AutopilotStatus(
            armed=self.phase != "disarmed",
            landed=self.phase in ("disarmed", "idle") or self._velocity_on_ground(),
            taking_off=self.phase == "takeoff",
            landing=self.phase == "land",
        )

    def _flying(self, what: str) -> None:
        if self.phase in ("disarmed", "idle"):
            raise ModelRefused(f"{what}: refused on the ground")

    def _armed(self, what: str) -> None:
        if self.phase == "disarmed":
            raise ModelRefused(f"{what}: refused while disarmed")

    def arm(self) -> None:
        self.calls.append(("arm",))
        if self.phase == "disarmed":
            self.phase = "idle"

    def disarm(self, force: bool) -> None:
        self.calls.append(("disarm", force))
        if not self.status().landed and not force:
            raise ModelRefused("disarm: refused in flight")
        self.phase = "disarmed"

    def takeoff(self, altitude_m: float) -> None:
        self.calls.append(("takeoff", altitude_m))
        if self.phase == "disarmed":
            raise ModelRefused("takeoff: refused while disarmed")
        self._target = np.array([self.position[0], self.position[1], -altitude_m])
        self.phase = "takeoff"

    def hold(self) -> None:
        self.calls.append(("hold",))
        if self._velocity_on_ground():
            self.phase = "idle"
            return
        self._flying("hold")
        self._target = self.position.copy()
        self.phase = "hold"

    def land(self) -> None:
        self.calls.append(("land",))
        if self._velocity_on_ground():
            self.phase = "idle"
        elif not self.status().landed:
            self.phase = "land"

    def set_velocity_body(
        self, forward_m_s: float, right_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        self.calls.append(("velocity_body", forward_m_s, right_m_s, down_m_s, yawspeed_deg_s))
        self._armed("set_velocity_body")
        self._command = (np.array([forward_m_s, right_m_s, down_m_s]), True, yawspeed_deg_s)
        self.phase = "velocity"

    def set_velocity_ned(
        self, north_m_s: float, east_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        self.calls.append(("velocity_ned", north_m_s, east_m_s, down_m_s, yawspeed_deg_s))
        self._armed("set_velocity_ned")
        self._command = (np.array([north_m_s, east_m_s, down_m_s]), False, yawspeed_deg_s)
        self.phase = "velocity"
