"""`FakeVehicle`: a kinematic stand-in for unit tests of the code around the flight backends.

Simulated clock, velocity that follows the command with a first-order lag, PX4's
client-visible rules (setpoint before offboard, takeoff only when armed), and a
record of every command that reached it, so tests can check what the safety
layer let through.
"""

from __future__ import annotations

import math

from core.frames import heading_to_world_ned
from flight.errors import CommandDeniedError
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityBody, VelocityNed
from flight.vehicle import Vehicle


class FakeVehicle(Vehicle):
    realtime = False

    def __init__(self, yaw_deg: float = 0.0, lag_s: float = 0.2, realtime: bool = False) -> None:
        self.realtime = realtime
        self.yaw_deg = yaw_deg
        self.lag_s = lag_s
        self.now_s = 0.0
        self.position = [0.0, 0.0, 0.0]
        self.velocity = [0.0, 0.0, 0.0]
        self.armed = False
        self.in_air = False
        self.mode = FlightMode.READY
        self.setpoint: VelocityBody | None = None
        self.commands: list[VelocityBody] = []
        self.calls: list[str] = []
        self.closed = False

    def _target_ned(self) -> tuple[float, float, float]:
        if self.mode != FlightMode.OFFBOARD or self.setpoint is None:
            return (0.0, 0.0, 0.0)
        sp = self.setpoint
        north, east = heading_to_world_ned(sp.forward_m_s, sp.right_m_s, math.radians(self.yaw_deg))
        return (north, east, sp.down_m_s)

    def sleep(self, seconds: float) -> None:
        steps = max(1, round(seconds / 0.01)) if seconds > 0 else 0
        for _ in range(steps):
            target = self._target_ned()
            alpha = min(1.0, 0.01 / self.lag_s)
            for i in range(3):
                self.velocity[i] += alpha * (target[i] - self.velocity[i])
                self.position[i] += self.velocity[i] * 0.01
            self.now_s += 0.01

    def time_s(self) -> float:
        return self.now_s

    def telemetry(self) -> Telemetry:
        return Telemetry(
            position_ned=PositionNed(*self.position),
            velocity_ned=VelocityNed(*self.velocity),
            attitude=Attitude(0.0, 0.0, self.yaw_deg),
            armed=self.armed,
            in_air=self.in_air,
            flight_mode=self.mode,
            timestamp_s=self.now_s,
        )

    def connect(self, timeout_s: float | None = None) -> None:
        self.calls.append("connect")

    def wait_ready(self, timeout_s: float | None = None) -> None:
        self.calls.append("wait_ready")

    def arm(self, timeout_s: float | None = None) -> None:
        self.calls.append("arm")
        self.armed = True

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self.calls.append("takeoff")
        if not self.armed:
            raise CommandDeniedError("takeoff()", "COMMAND_DENIED", "not armed")
        self.in_air = True
        self.position[2] = -altitude_m
        self.mode = FlightMode.HOLD

    def start_offboard(self, timeout_s: float | None = None) -> None:
        self.calls.append("start_offboard")
        if self.setpoint is None:
            raise CommandDeniedError("start_offboard()", "NO_SETPOINT_SET")
        self.mode = FlightMode.OFFBOARD

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        self.setpoint = velocity
        self.commands.append(velocity)

    def hold(self) -> None:
        self.calls.append("hold")
        if self.mode == FlightMode.OFFBOARD:
            self.set_velocity_body(VelocityBody())
        else:
            self.mode = FlightMode.HOLD

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self.calls.append("stop_offboard")
        if self.mode == FlightMode.OFFBOARD:
            self.mode = FlightMode.HOLD

    def land(self, timeout_s: float | None = None) -> None:
        self.calls.append("land")
        self.mode = FlightMode.LAND
        self.position[2] = 0.0
        self.in_air = False

    def disarm(self, timeout_s: float | None = None) -> None:
        self.calls.append("disarm")
        self.armed = False

    def close(self) -> None:
        self.calls.append("close")
        self.closed = True
