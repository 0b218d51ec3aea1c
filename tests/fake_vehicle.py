"""`FakeVehicle`: the one kinematic stand-in for unit tests of the code around the flight backends.

A point in NED on a simulated clock (time advances only in `sleep()`), with PX4's
client-visible rules (a setpoint before offboard, takeoff only when armed, velocity
commands act only in OFFBOARD) and a record of every call and command that reached
it, so a test can check what the safety layer or the loop let through.

Two ways to start:
- `FakeVehicle()` on the ground, facing `yaw_deg`: arming, takeoff (climbs to its
  altitude), offboard; velocity follows the command with a first-order lag `lag_s`
  (the flight-layer tests);
- `FakeVehicle.at_pose(east_m, up_m)`: already hovering in offboard at a pose in front
  of the target, facing north, velocity exact (lag 0) (the loop and mission tests, with
  `mission_fakes.FakeDetector` deriving the target's pixels from the pose).
`fail_on_move=N` raises on the N-th moving command (a link that dies mid-flight).
"""

from __future__ import annotations

import math

from drone_inspect_core.frames import heading_to_world_ned
from flight.errors import CommandDeniedError
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityBody, VelocityNed
from flight.vehicle import Vehicle

STEP_S = 0.01


class FakeVehicle(Vehicle):
    realtime = False

    def __init__(
        self,
        yaw_deg: float = 0.0,
        lag_s: float = 0.2,
        realtime: bool = False,
        fail_on_move: int | None = None,
    ) -> None:
        self.realtime = realtime
        self.yaw_deg = yaw_deg
        self.lag_s = lag_s
        self.fail_on_move = fail_on_move
        self.now_s = 0.0
        self.position = [0.0, 0.0, 0.0]  # NED from home
        self.velocity = [0.0, 0.0, 0.0]
        self.armed = False
        self.in_air = False
        self.mode = FlightMode.READY
        self.setpoint: VelocityBody | None = None
        self.commands: list[VelocityBody] = []
        self.calls: list[str] = []
        self.moves_commanded = 0
        self.closed = False
        self._takeoff_climbs = True

    @classmethod
    def at_pose(cls, east_m: float = 0.0, up_m: float = 0.0, fail_on_move: int | None = None) -> FakeVehicle:
        """Hovering in offboard `east_m` right of and `up_m` above the centred pose, exact kinematics."""
        vehicle = cls(lag_s=0.0, fail_on_move=fail_on_move)
        vehicle.position = [0.0, east_m, -up_m]
        vehicle.mode, vehicle.setpoint, vehicle._takeoff_climbs = FlightMode.OFFBOARD, VelocityBody(), False
        vehicle.armed = vehicle.in_air = True  # hovering
        return vehicle

    @property
    def east_m(self) -> float:
        return self.position[1]

    @property
    def up_m(self) -> float:
        return -self.position[2]

    # ------------------------------------------------------------------ physics
    def _target_ned(self) -> tuple[float, float, float]:
        if self.mode != FlightMode.OFFBOARD or self.setpoint is None:
            return (0.0, 0.0, 0.0)
        sp = self.setpoint
        north, east = heading_to_world_ned(sp.forward_m_s, sp.right_m_s, math.radians(self.yaw_deg))
        return (north, east, sp.down_m_s)

    def sleep(self, seconds: float) -> None:
        if seconds <= 0:
            return
        if self.lag_s == 0.0:  # exact: the velocity is the command
            self.velocity = list(self._target_ned())
            for i in range(3):
                self.position[i] += self.velocity[i] * seconds
            self.now_s += seconds
            return
        for _ in range(max(1, round(seconds / STEP_S))):
            target = self._target_ned()
            alpha = min(1.0, STEP_S / self.lag_s)
            for i in range(3):
                self.velocity[i] += alpha * (target[i] - self.velocity[i])
                self.position[i] += self.velocity[i] * STEP_S
            self.now_s += STEP_S

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

    # ----------------------------------------------------------------- commands
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
        if self._takeoff_climbs:
            self.position[2] = -altitude_m
            self.mode = FlightMode.HOLD

    def start_offboard(self, timeout_s: float | None = None) -> None:
        self.calls.append("start_offboard")
        if self.setpoint is None:
            raise CommandDeniedError("start_offboard()", "NO_SETPOINT_SET")
        self.mode = FlightMode.OFFBOARD

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        if not velocity.is_zero() and velocity != self.setpoint:
            self.moves_commanded += 1
            if self.fail_on_move is not None and self.moves_commanded >= self.fail_on_move:
                raise RuntimeError("FakeVehicle: simulated link failure")
        self.setpoint = velocity
        self.commands.append(velocity)
        if self.lag_s == 0.0:
            self.velocity = list(self._target_ned())

    def hold(self) -> None:
        self.calls.append("hold")
        if self.mode == FlightMode.OFFBOARD:
            self.set_velocity_body(VelocityBody())
        else:
            self.mode = FlightMode.HOLD

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self.calls.append("stop_offboard")
        if self.mode == FlightMode.OFFBOARD:
            self.setpoint = VelocityBody()
            self.velocity = [0.0, 0.0, 0.0] if self.lag_s == 0.0 else self.velocity
            self.mode = FlightMode.HOLD

    def land(self, timeout_s: float | None = None) -> None:
        self.calls.append("land")
        self.mode = FlightMode.LAND
        self.position[2] = 0.0
        self.in_air = False

    def disarm(self, timeout_s: float | None = None) -> None:
        self.calls.append("disarm")
        self.armed = False

    def kill(self, timeout_s: float | None = None) -> None:
        """Motors off at once: a flying fake drops to the ground."""
        self.calls.append("kill")
        self.armed = False
        self.mode = FlightMode.READY
        self.setpoint = None
        self.position[2] = 0.0
        self.velocity = [0.0, 0.0, 0.0]
        self.in_air = False

    def close(self) -> None:
        self.calls.append("close")
        self.closed = True
