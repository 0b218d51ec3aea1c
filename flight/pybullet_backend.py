"""`PyBulletVehicle`: the `Vehicle` interface over an in-process `sim_world.world.World`.

No link, no real time: the backend drives the world's autopilot directly and
advances the physics itself, only inside `sleep()` and the blocking calls, so a
flight runs as fast as the CPU allows and is deterministic for a given world
seed. It keeps PX4's client-visible rules (a setpoint before offboard, offboard
only when armed, refusals as typed errors) so that code tested here flies the
MAVSDK backend unchanged. Frames are converted only through `drone_inspect_core.frames`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable

import numpy as np

from drone_inspect_core.frames import enu_to_ned, yaw_enu_to_ned_rad
from flight.errors import CommandDeniedError, FlightTimeoutError
from flight.safety import FlightTimeouts
from flight.types import Attitude, FlightMode, PositionNed, Telemetry, VelocityBody, VelocityNed
from flight.vehicle import Vehicle
from sim_world.physics.autopilot import AutopilotError, AutopilotMode
from sim_world.world import World, WorldConfig

log = logging.getLogger(__name__)

_MODES = {
    AutopilotMode.DISARMED: FlightMode.READY,
    AutopilotMode.IDLE: FlightMode.READY,
    AutopilotMode.TAKEOFF: FlightMode.TAKEOFF,
    AutopilotMode.HOLD: FlightMode.HOLD,
    AutopilotMode.VELOCITY: FlightMode.OFFBOARD,
    AutopilotMode.LAND: FlightMode.LAND,
}


PACED_CHUNK_STEPS = 4
"""A paced clock steps this many physics steps at a time (1/60 s at 240 Hz) between its waits."""
PACE_SLACK_S = 0.25


class PyBulletVehicle(Vehicle):
    """Flies `world` in simulated time. Owns the world (and closes it) only when built by `create()`."""

    realtime = False

    def __init__(
        self,
        world: World,
        timeouts: FlightTimeouts | None = None,
        altitude_tolerance_m: float = 0.3,
        owns_world: bool = False,
    ) -> None:
        self.world = world
        self._pace: float | None = None  # simulated seconds per wall second; None: as fast as it goes
        self._pace_origin = (0.0, 0.0)  # (simulated, wall) time when the pace was last set or lost
        self._step_lock = threading.Lock()
        self.timeouts = timeouts or FlightTimeouts()
        self.altitude_tolerance_m = altitude_tolerance_m
        self._owns_world = owns_world
        self._setpoint: VelocityBody | None = None
        self._offboard = False
        # Local positions are relative to home, as MAVLink's LOCAL_POSITION_NED; before the first
        # arming (which sets home) they are relative to where the drone stood when handed over.
        self._origin_enu = np.asarray(world.state().position_enu_m, dtype=float)

    @classmethod
    def create(cls, config: WorldConfig | None = None, seed: int = 0, **kwargs: object) -> PyBulletVehicle:
        """A vehicle in a new world of its own, built from `seed` (closed with the vehicle)."""
        return cls(World(config, seed), owns_world=True, **kwargs)  # type: ignore[arg-type]

    # --- clock --------------------------------------------------------------------------------
    def time_s(self) -> float:
        return self.world.time_s

    def sleep(self, seconds: float) -> None:
        """Step the physics for at least `seconds` of simulated time (whole steps, rounded up).

        Like `time.sleep`, a sleep never ends early: any positive sleep advances the
        clock by at least one physics step, so a caller waiting for the clock to pass
        a deadline always gets there.
        """
        steps = math.ceil(max(0.0, seconds) / self.world.dt_s - 1e-9)
        if self._pace is None:
            self.world.step(steps)
            return
        end_s = self.time_s() + (steps - 1e-6) * self.world.dt_s
        while self.time_s() < end_s:
            with self._step_lock:  # several threads may sleep at once: the clock still keeps its pace
                chunk = min(PACED_CHUNK_STEPS, math.ceil((end_s - self.time_s()) / self.world.dt_s))
                if chunk <= 0:
                    return
                self._wait_for_pace()
                self.world.step(chunk)

    def set_pace(self, speed: float | None) -> None:
        """Run the simulated clock at most `speed` simulated seconds per wall second (1.0: real time, for
        a person watching; None: as fast as the CPU goes, the default). Safe to call from any thread;
        `sleep()` may then be called from several threads at once (each returns when the clock has
        passed its own end), which lets a live view keep the world moving between a client's calls."""
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"pace must be a number > 0 or None, got {speed!r}")
        with self._step_lock:
            self._pace = speed
            self._pace_origin = (self.time_s(), time.monotonic())

    def _wait_for_pace(self) -> None:
        """Wait (holding the step lock) until the wall clock has caught up with the simulated one; a
        clock that fell behind by more than `PACE_SLACK_S` (a loaded machine) starts again from now
        rather than racing to catch up."""
        assert self._pace is not None
        sim0, wall0 = self._pace_origin
        ahead_s = (self.time_s() - sim0) / self._pace - (time.monotonic() - wall0)
        if ahead_s > 0:
            time.sleep(ahead_s)
        elif ahead_s < -PACE_SLACK_S:
            self._pace_origin = (self.time_s(), time.monotonic())

    def _step_until(
        self, predicate: Callable[[Telemetry], bool], timeout_s: float, origin: str, what: str
    ) -> None:
        deadline = self.time_s() + timeout_s
        while not predicate(self.telemetry()):
            if self.time_s() >= deadline:
                raise FlightTimeoutError(origin, timeout_s, what)
            self.sleep(0.02)

    # --- telemetry ----------------------------------------------------------------------------
    def telemetry(self) -> Telemetry:
        state = self.world.state()
        autopilot = self.world.autopilot
        home = autopilot.home_enu_m
        origin = self._origin_enu if home is None else home
        north, east, down = enu_to_ned(np.asarray(state.position_enu_m) - origin)
        vn, ve, vd = enu_to_ned(state.velocity_enu_m_s)
        return Telemetry(
            position_ned=PositionNed(float(north), float(east), float(down)),
            velocity_ned=VelocityNed(float(vn), float(ve), float(vd)),
            # FLU → FRD: roll keeps its sign, pitch flips (FLU pitch about +left is nose down).
            attitude=Attitude(
                math.degrees(state.roll_enu_rad),
                -math.degrees(state.pitch_enu_rad),
                math.degrees(yaw_enu_to_ned_rad(state.yaw_enu_rad)),
            ),
            armed=autopilot.armed,
            in_air=not autopilot.landed,
            flight_mode=_MODES.get(autopilot.mode, FlightMode.OTHER),
            timestamp_s=self.time_s(),
            forward_range_m=self.world.forward_range_m(),
        )

    # --- commands -----------------------------------------------------------------------------
    def connect(self, timeout_s: float | None = None) -> None:
        """Nothing to open: the world is in this process. One physics step gives the autopilot a state."""
        if self.world.time_s == 0.0:
            self.world.step(1)

    def wait_ready(self, timeout_s: float | None = None) -> None:
        """The simulated state estimate and home are valid from the first step."""

    def _autopilot_call(self, origin: str, call: Callable[[], None]) -> None:
        try:
            call()
        except AutopilotError as exc:
            raise CommandDeniedError(origin, "COMMAND_DENIED", str(exc)) from None

    def arm(self, timeout_s: float | None = None) -> None:
        self._autopilot_call("arm()", self.world.autopilot.arm)

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude must be a positive number of metres, got {altitude_m!r}")
        self._autopilot_call("takeoff()", lambda: self.world.autopilot.takeoff(altitude_m))
        target_m = altitude_m - self.altitude_tolerance_m
        self._step_until(
            lambda t: t.in_air and -t.position_ned.down_m >= target_m and abs(t.velocity_ned.down_m_s) < 0.2,
            timeout_s or self.timeouts.takeoff_s,
            "takeoff()",
            f"altitude {target_m:.2f} m and the climb ending",
        )

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        self._setpoint = velocity
        if self._offboard:
            self._send(velocity)

    def _send(self, v: VelocityBody) -> None:
        self._autopilot_call(
            "set_velocity_body()",
            lambda: self.world.autopilot.set_velocity_body(
                v.forward_m_s, v.right_m_s, v.down_m_s, v.yawspeed_deg_s
            ),
        )

    def start_offboard(self, timeout_s: float | None = None) -> None:
        if self._setpoint is None:
            raise CommandDeniedError(
                "start_offboard()",
                "NO_SETPOINT_SET",
                "set a velocity setpoint first: PX4 needs a setpoint stream",
            )
        if not self.world.autopilot.armed:
            raise CommandDeniedError("start_offboard()", "COMMAND_DENIED", "the vehicle is not armed")
        self._send(self._setpoint)
        self._offboard = True

    def hold(self) -> None:
        if self._offboard:
            self.set_velocity_body(VelocityBody())
        else:
            self._autopilot_call("hold()", self.world.autopilot.hold)

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        if self._offboard:
            self._offboard = False
            self._autopilot_call("stop_offboard()", self.world.autopilot.hold)

    def land(self, timeout_s: float | None = None) -> None:
        self.stop_offboard()
        self._autopilot_call("land()", self.world.autopilot.land)
        self._step_until(lambda t: not t.in_air, timeout_s or self.timeouts.land_s, "land()", "landed state")

    def disarm(self, timeout_s: float | None = None) -> None:
        if self.world.autopilot.armed:
            self._autopilot_call("disarm()", self.world.autopilot.disarm)

    def kill(self, timeout_s: float | None = None) -> None:
        """Stop the rotors at once (the autopilot's forced disarm): in the air the drone falls."""
        self._offboard = False
        self._autopilot_call("kill()", lambda: self.world.autopilot.disarm(force=True))

    def close(self) -> None:
        if self._owns_world:
            self.world.close()
