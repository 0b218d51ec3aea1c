"""`Px4Bridge`: the lockstep loop between the PyBullet world and PX4 SITL.

Each tick of `sensor_period_s` (4 ms) of simulated time:

1. read the truth (pose, velocity, the acceleration over the last tick, body rates);
2. send HIL_SENSOR at the tick's time (IMU always, magnetometer and barometer at
   their rates), HIL_GPS every `gps_period_s`, HIL_STATE_QUATERNION as truth;
3. wait for PX4's HIL_ACTUATOR_CONTROLS for that time (lockstep: PX4's clock is the
   sensor time, so PX4 never misses a deadline however slow this loop is);
4. turn the motor outputs into rotor speed commands and step the physics one tick;
5. hand the pose to the camera every 1/`camera_fps` of simulated time; the forward rangefinder goes to
   PX4 as DISTANCE_SENSOR every `range_every` ticks (PX4 streams it on to its clients);
6. with a finite `speed`, sleep until the wall clock catches up (× speed).

Before PX4's first answer (it is still booting) the loop waits a short while for
each answer and then goes on with the motors off, so boot does not stall.

Kept warm between missions, `rebase(world, origin)` puts the next mission's world (freshly built)
behind the running PX4: PX4 senses it through an `AutopilotFrame` in which the new start is where and
when PX4 last saw the drone, so its estimator, its clock and its IMU run on without a jump.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sim_world.px4_bridge.geodesy import HomePoint
from sim_world.px4_bridge.link import Px4DisconnectedError, SimulatorServer
from sim_world.px4_bridge.messages import ActuatorCommand, HilEncoder, RotorMapping, actuator_command
from sim_world.px4_bridge.sensors import SensorSuite, Truth
from sim_world.sitl.frame import AutopilotFrame
from sim_world.sitl.rig import CameraClock, LockstepPace, TruthReader, continue_in, run_lockstep
from sim_world.vehicle.telemetry import distance_sensor_message
from sim_world.world import World

log = logging.getLogger(__name__)

PX4_CLOCK_OFFSET_US = 20_000_000
"""PX4's clock = simulated time + 20 s. Started near 0, PX4's first integrated IMU sample spans
everything since 0 and EKF2 began with ~1.8 m/s of vertical velocity on a vehicle at rest
(its height then settled 0.5-1 m off); Gazebo's world clock is well past 0 when PX4 connects."""


@dataclass(frozen=True)
class BridgeTiming:
    """Rates (simulated time) and waits (wall time) of the lockstep loop."""

    sensor_period_s: float = 0.004  # HIL_SENSOR at 250 Hz, PX4's IMU_INTEG_RATE in SITL
    mag_every: int = 2  # 125 Hz
    baro_every: int = 5  # 50 Hz
    gps_every: int = 25  # 10 Hz
    truth_every: int = 5  # HIL_STATE_QUATERNION at 50 Hz
    range_every: int = 25  # DISTANCE_SENSOR (the forward rangefinder) at 10 Hz
    camera_fps: float = 30.0
    speed: float | None = 1.0  # simulated s per wall s; None: as fast as PX4 and the physics go
    boot_answer_wait_s: float = 0.005  # before PX4's first answer
    answer_timeout_s: float = 2.0  # in lockstep: no answer this long (wall) = PX4 stalled
    px4_silent_timeout_s: float = 3.0  # nothing at all from PX4 this long = PX4 gone

    def __post_init__(self) -> None:
        if not 0.001 <= self.sensor_period_s <= 0.02:
            raise ValueError(f"sensor_period_s must be in [0.001, 0.02], got {self.sensor_period_s}")
        if self.speed is not None and not (math.isfinite(self.speed) and 0.05 <= self.speed <= 100.0):
            raise ValueError(f"speed must be in [0.05, 100] or None (as fast as possible), got {self.speed}")
        if not 1.0 <= self.camera_fps <= 120.0:
            raise ValueError(f"camera_fps must be in [1, 120], got {self.camera_fps}")
        if min(self.mag_every, self.baro_every, self.gps_every, self.truth_every, self.range_every) < 1:
            raise ValueError("sensor rate dividers must be >= 1")


@dataclass
class BridgeStats:
    """What the loop measured; `Px4Bridge.stats()` returns a copy."""

    ticks: int = 0
    sim_s: float = 0.0
    wall_s: float = 0.0
    answers: int = 0  # HIL_ACTUATOR_CONTROLS received
    late_answers: int = 0  # ticks that went on without PX4's answer after lockstep began
    camera_frames: int = 0
    armed: bool = False
    lockstep: bool = False
    first_answer_sim_s: float | None = None
    messages_from_px4: dict[str, int] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else 0.0


class Px4Bridge:
    """The world behind PX4's simulator link. `run()` blocks until `stop` is set or PX4 goes away."""

    def __init__(
        self,
        world: World,
        server: SimulatorServer,
        sensors: SensorSuite,
        home: HomePoint,
        timing: BridgeTiming | None = None,
        camera: CameraClock | None = None,
        origin_enu_m: np.ndarray | None = None,
    ) -> None:
        self.world, self.server, self.sensors, self.home = world, server, sensors, home
        self.timing = timing or BridgeTiming()
        self.camera = camera
        self.origin_enu_m = world.state().position_enu_m.copy() if origin_enu_m is None else origin_enu_m
        self.mapping = RotorMapping.for_quad(world.drone.params)
        self._encoder = HilEncoder()
        self._substeps = max(1, round(self.timing.sensor_period_s / world.dt_s))
        if abs(self._substeps * world.dt_s - self.timing.sensor_period_s) > 1e-9:
            raise ValueError(
                f"physics step {world.dt_s * 1000:.3f} ms does not divide the sensor period "
                f"{self.timing.sensor_period_s * 1000:.1f} ms (use physics_hz = k × 250)"
            )
        self._time_usec = 0
        self._command: ActuatorCommand | None = None
        self._last_heard = time.monotonic()
        self._truth_reader = TruthReader(world, self.origin_enu_m, self.timing.sensor_period_s)
        self.frame = AutopilotFrame()
        self.last_truth: Truth | None = None
        """What PX4 was last told (its frame)."""
        self.rebased_at_s: float | None = None
        """PX4's clock (its `time_boot`, s) when the last `rebase`'s world began."""
        self._stats = BridgeStats()
        self._stats_lock = threading.Lock()
        world.drone.stop_rotors()

    # ------------------------------------------------------------------ queries
    def stats(self) -> BridgeStats:
        with self._stats_lock:
            copy = BridgeStats(
                **{**vars(self._stats), "messages_from_px4": dict(self._stats.messages_from_px4)}
            )
        return copy

    @property
    def time_usec(self) -> int:
        """PX4's clock: the time of the last HIL_SENSOR sent."""
        return self._time_usec

    def rebase(self, world: World, origin_enu_m: np.ndarray) -> None:
        """Fly `world` (a fresh build, the drone landed and still) from the next tick on, shown to PX4 as
        the continuation of what it last saw (`AutopilotFrame.continuing`); the old world is the caller's."""
        period_s = self.timing.sensor_period_s
        next_time_s = (self._time_usec - PX4_CLOCK_OFFSET_US) / 1e6 + period_s
        reader, self.frame = continue_in(
            world, origin_enu_m, period_s, self.last_truth, next_time_s, self.camera
        )
        self.rebased_at_s = next_time_s + PX4_CLOCK_OFFSET_US / 1e6  # PX4's own clock (time_boot)
        self.world, self.origin_enu_m, self._truth_reader = world, origin_enu_m, reader

    # --------------------------------------------------------------------- loop
    def run(
        self,
        stop: threading.Event,
        max_sim_s: float | None = None,
        between: Callable[[], None] | None = None,
        pace: LockstepPace | None = None,
    ) -> BridgeStats:
        """Lockstep until `stop`, `max_sim_s` of simulated time, or PX4 disconnects (re-raised);
        `between()` between two ticks, every `rig.BETWEEN_S` of wall time (a warm simulator's resets);
        `pace`: the client holds the world too (`rig.LockstepPace`)."""
        self._last_heard = time.monotonic()
        run_lockstep(
            lambda: self.world, self.step, stop, self.timing.speed, max_sim_s, between, self._wall, pace
        )
        return self.stats()

    def _wall(self, seconds: float) -> None:
        with self._stats_lock:
            self._stats.wall_s = seconds

    def step(self) -> None:
        """One sensor period: sensors out, PX4's answer in, physics one tick."""
        timing, world = self.timing, self.world
        tick = self._stats.ticks
        truth = self.last_truth = self.frame.apply(self._truth_reader.read())
        self._time_usec = round(truth.time_s * 1e6) + PX4_CLOCK_OFFSET_US
        imu = self.sensors.imu(truth)
        mag = self.sensors.mag(truth) if tick % timing.mag_every == 0 else None
        baro = self.sensors.baro(truth) if tick % timing.baro_every == 0 else None
        out = [self._encoder.hil_sensor(self._time_usec, imu, mag, baro)]
        if tick % timing.gps_every == 0:
            out.append(self._encoder.hil_gps(self._time_usec, self.sensors.gps(truth)))
        if tick % timing.truth_every == 0:
            north, east, down = truth.position_ned_m.tolist()
            out.append(
                self._encoder.hil_state_quaternion(
                    self._time_usec, truth, self.home.to_global(north, east, down)
                )
            )
        if tick % timing.range_every == 0:
            message = distance_sensor_message(round(truth.time_s * 1000), world.forward_range_m())
            out.append(self._encoder.pack(message))
        self.server.send(b"".join(out))
        self._await_answer(self._time_usec)
        rotors = self.mapping.rotor_speeds(self._command)
        world.step_rotors(rotors, self._substeps)
        if self.camera is not None:
            self.camera.tick(world.time_s)
        with self._stats_lock:
            st = self._stats
            st.ticks += 1
            st.sim_s = world.time_s
            st.armed = bool(self._command and self._command.armed)
            st.camera_frames = self.camera.frames if self.camera else 0

    def _await_answer(self, time_usec: int) -> None:
        """Read PX4's messages until the actuator answer for `time_usec` (or give up, see the module doc).

        Once PX4 has answered anything, the wait is the long lockstep one (an answer for an earlier
        tick arriving late switches it on at once).
        """
        timing = self.timing
        start = time.monotonic()
        while True:
            wait_s = timing.answer_timeout_s if self._stats.lockstep else timing.boot_answer_wait_s
            left = start + wait_s - time.monotonic()
            for frame in self.server.receive(max(0.0, left)):
                self._last_heard = time.monotonic()
                name = frame.name
                counts = self._stats.messages_from_px4
                counts[name] = counts.get(name, 0) + 1
                if frame.msg_id == mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS:
                    command = actuator_command(frame.payload)
                    self._command = command
                    self._stats.answers += 1
                    if not self._stats.lockstep:
                        self._stats.lockstep = True
                        self._stats.first_answer_sim_s = self.world.time_s
                        log.info("PX4 answers: lockstep from %.3f s of simulated time", self.world.time_s)
                    if command.time_usec >= time_usec:
                        return
            if time.monotonic() - self._last_heard > timing.px4_silent_timeout_s:
                raise Px4DisconnectedError(
                    f"PX4 sent nothing for {timing.px4_silent_timeout_s:.1f} s on the simulator link"
                )
            wait_s = timing.answer_timeout_s if self._stats.lockstep else timing.boot_answer_wait_s
            if time.monotonic() - start >= wait_s:  # the wait as it stands now: lockstep may have begun
                if self._stats.lockstep:
                    self._stats.late_answers += 1
                    log.warning("no PX4 answer for t=%d us within %.1f s: stepping on", time_usec, wait_s)
                return
