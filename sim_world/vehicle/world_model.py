"""`VehicleModel` over the real PyBullet `World`: frames converted once, autopilot errors mapped.

The local NED origin (PX4's EKF origin and home) is where the drone rests when the
vehicle starts, so LOCAL_POSITION_NED reads ~0 on the ground and −MIS_TAKEOFF_ALT
after a takeoff. The world is not thread-safe: only the vehicle loop may touch it
while the vehicle runs.
"""

from __future__ import annotations

from typing import Any

from drone_inspect_core.frames import enu_to_ned, flu_to_frd, yaw_enu_to_ned_rad
from sim_world.physics.autopilot import AutopilotError, AutopilotMode
from sim_world.vehicle.model import AutopilotStatus, Kinematics, ModelRefused
from sim_world.world import World


class WorldVehicleModel:
    """The airframe of a `World` as the MAVLink layer sees it."""

    def __init__(self, world: World):
        self.world = world
        self.origin_enu_m = world.state().position_enu_m.copy()

    @property
    def physics_hz(self) -> float:
        return self.world.config.physics_hz

    @property
    def time_s(self) -> float:
        return self.world.time_s

    def step(self, n: int) -> None:
        self.world.step(n)

    def kinematics(self) -> Kinematics:
        s = self.world.state()
        return Kinematics(
            time_s=self.world.time_s,
            position_ned_m=enu_to_ned(s.position_enu_m - self.origin_enu_m),
            velocity_ned_m_s=enu_to_ned(s.velocity_enu_m_s),
            roll_rad=s.roll_enu_rad,  # same rotation in FLU and FRD
            pitch_rad=-s.pitch_enu_rad,  # FLU pitch lowers the nose, FRD pitch raises it
            yaw_rad=yaw_enu_to_ned_rad(s.yaw_enu_rad),
            rates_frd_rad_s=flu_to_frd(s.angular_velocity_flu_rad_s),
            forward_range_m=self.world.forward_range_m(),
        )

    def status(self) -> AutopilotStatus:
        ap = self.world.autopilot
        return AutopilotStatus(
            armed=ap.armed,
            landed=ap.landed,
            taking_off=ap.mode is AutopilotMode.TAKEOFF,
            landing=ap.mode is AutopilotMode.LAND,
        )

    def arm(self) -> None:
        self._call(self.world.autopilot.arm)

    def disarm(self, force: bool) -> None:
        self._call(self.world.autopilot.disarm, force)

    def takeoff(self, altitude_m: float) -> None:
        self._call(self.world.autopilot.takeoff, altitude_m)

    def hold(self) -> None:
        self._call(self.world.autopilot.hold)

    def land(self) -> None:
        self._call(self.world.autopilot.land)

    def set_velocity_body(
        self, forward_m_s: float, right_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        self._call(self.world.autopilot.set_velocity_body, forward_m_s, right_m_s, down_m_s, yawspeed_deg_s)

    def set_velocity_ned(
        self, north_m_s: float, east_m_s: float, down_m_s: float, yawspeed_deg_s: float
    ) -> None:
        self._call(self.world.autopilot.set_velocity_ned, north_m_s, east_m_s, down_m_s, yawspeed_deg_s)

    @staticmethod
    def _call(fn: Any, *args: Any) -> None:
        try:
            fn(*args)
        except AutopilotError as exc:
            raise ModelRefused(str(exc)) from exc
