"""`ArduPilotBridge`: the lockstep loop between the PyBullet world and ArduPilot's JSON interface.

Each servo packet ArduPilot sends is one physics frame:

1. the four motor PWMs become rotor speed commands (`motors.PwmToRotor`, quad X);
2. the world steps `frame_period_s` of simulated time (ArduPilot waits meanwhile: its clock is
   the `timestamp` it is sent, so nothing here can make it miss a deadline);
3. the reply carries the new state: simulated time, gyro and specific force with IMU noise
   (`sim_world.sitl.imu`), NED position and velocity, the attitude quaternion, and the forward
   rangefinder (a ray along the body's forward axis to the first surface, at `rangefinder_every`);
4. the camera takes a pose every 1/fps of simulated time (1/`idle_camera_fps` while no motor spins:
   ArduPilot boots for ~41 s of simulated time, disarmed on the ground, and nothing reads the camera
   before a takeoff; at 30 Hz the 224 px rendering held that boot to ~2× real time);
5. with a finite `speed`, the loop sleeps until the wall clock catches up (× speed).

A packet with the frame number already answered is ArduPilot re-sending (our answer was lost or
late): it gets the same answer again and the world does not step. A frame number that goes back
means ArduPilot restarted: refused (`ArduPilotRestartedError`), since its estimator would begin on a
vehicle already in flight.

Kept warm between missions, `rebase(world, origin)` puts the next mission's world (freshly built)
behind the running ArduPilot, shown through an `AutopilotFrame` in which the new start is where and
when ArduPilot last saw the drone: its EKF (ready after ~40 simulated seconds from boot) runs on.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as p

from sim_world.ardupilot_bridge.link import ArduPilotSilentError, JsonPhysicsServer
from sim_world.ardupilot_bridge.motors import PwmToRotor
from sim_world.ardupilot_bridge.protocol import ServoPacket, state_json
from sim_world.px4_bridge.messages import quaternion_wxyz
from sim_world.sitl.frame import AutopilotFrame
from sim_world.sitl.imu import ImuModel, Truth
from sim_world.sitl.rig import CameraClock, LockstepPace, TruthReader, continue_in, run_lockstep
from sim_world.world import World

log = logging.getLogger(__name__)


class ArduPilotRestartedError(ConnectionError):
    """ArduPilot's frame count went back to the start: it restarted under a running world."""


@dataclass(frozen=True)
class JsonTiming:
    """Rates (simulated time) and waits (wall time) of the lockstep loop."""

    frame_period_s: float = 0.0025  # 400 Hz: ArduPilot's SIM_RATE_HZ, which the params file sets to match
    camera_fps: float = 30.0
    idle_camera_fps: float | None = 2.0  # while no motor spins (booting, disarmed); None: camera_fps always
    speed: float | None = 1.0  # simulated s per wall s; None: as fast as ArduPilot and the physics go
    rangefinder_every: int = 8  # frames between rangefinder rays (50 Hz at 400 Hz)
    rangefinder_max_m: float = 12.0
    silent_timeout_s: float = 3.0  # no servo packet this long (wall) once lockstep began = ArduPilot gone

    def __post_init__(self) -> None:
        if not 0.0005 <= self.frame_period_s <= 0.02:
            raise ValueError(f"frame_period_s must be in [0.0005, 0.02], got {self.frame_period_s}")
        if self.speed is not None and not (math.isfinite(self.speed) and 0.05 <= self.speed <= 100.0):
            raise ValueError(f"speed must be in [0.05, 100] or None (as fast as possible), got {self.speed}")
        if not 1.0 <= self.camera_fps <= 120.0:
            raise ValueError(f"camera_fps must be in [1, 120], got {self.camera_fps}")
        if self.idle_camera_fps is not None and not 0.1 <= self.idle_camera_fps <= self.camera_fps:
            raise ValueError(f"idle_camera_fps must be in [0.1, camera_fps] or None: {self.idle_camera_fps}")
        if self.rangefinder_every < 1 or not self.rangefinder_max_m > 0.5:
            raise ValueError("rangefinder_every must be >= 1 and rangefinder_max_m > 0.5")

    @property
    def frame_rate_hz(self) -> float:
        return 1.0 / self.frame_period_s


@dataclass
class JsonBridgeStats:
    """What the loop measured; `ArduPilotBridge.stats()` returns a copy."""

    frames: int = 0
    sim_s: float = 0.0
    wall_s: float = 0.0
    repeats: int = 0  # frames ArduPilot sent again (answered again, world not stepped)
    skipped: int = 0  # frame numbers that never arrived
    camera_frames: int = 0
    motors_spinning: bool = False
    ardupilot_rate_hz: int = 0  # the frame rate ArduPilot says it runs at
    lockstep: bool = False

    @property
    def real_time_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else 0.0


class ArduPilotBridge:
    """The world behind ArduPilot's JSON link. `run()` blocks until `stop`, or raises when ArduPilot goes."""

    def __init__(
        self,
        world: World,
        server: JsonPhysicsServer,
        imu: ImuModel,
        timing: JsonTiming | None = None,
        camera: CameraClock | None = None,
        origin_enu_m: np.ndarray | None = None,
    ) -> None:
        self.world, self.server, self.imu = world, server, imu
        self.timing = timing or JsonTiming()
        self.camera = camera
        self.origin_enu_m = world.state().position_enu_m.copy() if origin_enu_m is None else origin_enu_m
        self.mapping = PwmToRotor(max_rad_s=world.drone.params.max_rotor_speed_rad_s)
        self._substeps = max(1, round(self.timing.frame_period_s / world.dt_s))
        if abs(self._substeps * world.dt_s - self.timing.frame_period_s) > 1e-9:
            raise ValueError(
                f"physics step {world.dt_s * 1000:.3f} ms does not divide the frame period "
                f"{self.timing.frame_period_s * 1000:.2f} ms"
            )
        self._truth = TruthReader(world, self.origin_enu_m, self.timing.frame_period_s)
        self.frame = AutopilotFrame()
        self.last_truth: Truth | None = None
        """What ArduPilot was last told (its frame)."""
        self.rebased_at_s: float | None = None
        """ArduPilot's clock (the timestamps it is sent, s) when the last `rebase`'s world began."""
        self._last_frame: int | None = None
        self._last_reply = b""
        self._range_m = math.inf
        self._next_idle_frame_s = 0.0
        self._last_heard = time.monotonic()
        self._stats = JsonBridgeStats()
        self._stats_lock = threading.Lock()
        world.drone.stop_rotors()

    def stats(self) -> JsonBridgeStats:
        with self._stats_lock:
            return JsonBridgeStats(**vars(self._stats))

    def rebase(self, world: World, origin_enu_m: np.ndarray) -> None:
        """Fly `world` (a fresh build, the drone landed and still) from the next frame on, shown to
        ArduPilot as the continuation of what it last saw; the old world is the caller's."""
        # The next reply comes one frame after the new world's start, one frame after the last one sent.
        last = self.last_truth
        next_time_s = 0.0 if last is None else last.time_s
        period_s = self.timing.frame_period_s
        reader, self.frame = continue_in(world, origin_enu_m, period_s, last, next_time_s, self.camera)
        self.world, self.origin_enu_m, self._truth = world, origin_enu_m, reader
        self._next_idle_frame_s = 0.0
        self.rebased_at_s = next_time_s + period_s  # ArduPilot's clock: the next reply's timestamp

    # --------------------------------------------------------------------- loop
    def run(
        self,
        stop: threading.Event,
        max_sim_s: float | None = None,
        between: Callable[[], None] | None = None,
        pace: LockstepPace | None = None,
    ) -> JsonBridgeStats:
        """Lockstep until `stop`, `max_sim_s` of simulated time, or ArduPilot goes silent (raised);
        `between()` between two frames, every `rig.BETWEEN_S` of wall time (a warm simulator's resets);
        `pace`: the client holds the world too (`rig.LockstepPace`)."""
        self._last_heard = time.monotonic()

        def tick() -> None:
            self.serve_one(timeout_s=0.1)

        run_lockstep(lambda: self.world, tick, stop, self.timing.speed, max_sim_s, between, self._wall, pace)
        return self.stats()

    def _wall(self, seconds: float) -> None:
        with self._stats_lock:
            self._stats.wall_s = seconds

    def serve_one(self, timeout_s: float) -> bool:
        """Answer one servo packet if one arrives within `timeout_s`; True when one did."""
        packet = self.server.receive(timeout_s)
        now = time.monotonic()
        if packet is None:
            if self._stats.lockstep and now - self._last_heard > self.timing.silent_timeout_s:
                raise ArduPilotSilentError(
                    f"ArduPilot sent no servo packet for {self.timing.silent_timeout_s:.1f} s on "
                    f"UDP port {self.server.address[1]}"
                )
            return False
        self._last_heard = now
        self.step(packet)
        return True

    def step(self, packet: ServoPacket) -> None:
        """One frame: ArduPilot's PWMs in, the physics one frame on, the new state back."""
        last = self._last_frame
        if last is not None and packet.frame_count == last:
            self.server.reply(self._last_reply)
            with self._stats_lock:
                self._stats.repeats += 1
            return
        if last is not None and packet.frame_count < last:
            raise ArduPilotRestartedError(
                f"ArduPilot's frame count went from {last} back to {packet.frame_count}: it restarted"
            )
        world, timing = self.world, self.timing
        world.step_rotors(self.mapping.rotor_speeds(packet.pwm_us), self._substeps)
        world_truth = self._truth.read()
        truth = self.last_truth = self.frame.apply(world_truth)
        imu = self.imu.read(truth)
        frames = self._stats.frames
        if frames % timing.rangefinder_every == 0:
            self._range_m = self._forward_range_m(world_truth.rotation_ned_frd)
        reply = state_json(
            truth.time_s,
            imu.gyro_frd_rad_s.tolist(),
            imu.accel_frd_m_s2.tolist(),
            truth.position_ned_m.tolist(),
            truth.velocity_ned_m_s.tolist(),
            quaternion_wxyz(truth.rotation_ned_frd),
            (self._range_m,),
        )
        self._last_reply, self._last_frame = reply, packet.frame_count
        spinning = self.mapping.spinning(packet.pwm_us)
        if self.camera is not None:
            self._camera_tick(world.time_s, spinning)
        with self._stats_lock:
            st = self._stats
            if last is not None:
                st.skipped += packet.frame_count - last - 1
            st.frames += 1
            st.sim_s = world.time_s
            st.lockstep = True
            st.ardupilot_rate_hz = packet.frame_rate_hz
            st.motors_spinning = spinning
            st.camera_frames = self.camera.frames if self.camera else 0
        self.server.reply(reply)  # last: whoever reads the reply finds the frame counted

    def _camera_tick(self, sim_s: float, spinning: bool) -> None:
        """A camera pose at `camera_fps`, or at `idle_camera_fps` while no motor spins."""
        assert self.camera is not None
        idle_fps = self.timing.idle_camera_fps
        if spinning or idle_fps is None:
            self.camera.tick(sim_s)
        elif sim_s + 1e-9 >= self._next_idle_frame_s:
            self.camera.tick(sim_s)
            self._next_idle_frame_s = sim_s + 1.0 / idle_fps

    def _forward_range_m(self, rotation_ned_frd: np.ndarray) -> float:
        """Distance along the body's forward axis to the first surface (the drone's own body excluded);
        twice the maximum when nothing is in range (ArduPilot then reports out of range)."""
        world = self.world
        forward_enu = np.array([rotation_ned_frd[1, 0], rotation_ned_frd[0, 0], -rotation_ned_frd[2, 0]])
        start_m = world.drone.params.body_half_extents_m[0] + 0.05  # outside the drone's collision box
        origin = world.state().position_enu_m
        max_m = self.timing.rangefinder_max_m
        hit = p.rayTest(
            (origin + start_m * forward_enu).tolist(),
            (origin + max_m * forward_enu).tolist(),
            physicsClientId=world.client_id,
        )[0]
        if hit[0] < 0 or hit[0] == world.drone.body_id:
            return 2.0 * max_m
        return start_m + hit[2] * (max_m - start_m)
