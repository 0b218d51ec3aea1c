"""The simulated side of an autopilot in the loop: the quadrotor, its world, its truth and its camera clock.

An external autopilot (PX4 or ArduPilot SITL) boots with the drone resting on the floor below the
mission's start pose, rotors stopped; the autopilot then flies it through the rotor speed commands
its bridge derives from the motor outputs. Truth is what the bridge reports to the autopilot (before
noise) and what judges a flight; it is expressed in the autopilot's frames: NED position and
velocity from the start point, body FRD rates, the body-to-NED rotation.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np
import pybullet as p

from drone_inspect_core.frames import enu_to_ned
from drone_inspect_core.world_options import StartPose, WindConfig
from sim_world.physics.quadrotor import QuadrotorParams
from sim_world.process_entry import LauncherRequests
from sim_world.rendering.camera import CameraConfig
from sim_world.scene.config import SceneConfig
from sim_world.sitl.frame import AutopilotFrame
from sim_world.sitl.imu import Truth
from sim_world.world import World, WorldConfig

SITL_QUAD = QuadrotorParams(landing_gear_stiffness_n_m=3000.0)
"""The project's quadrotor with compliant landing legs (3 mm static deflection, damped): with
PyBullet's rigid contact a touchdown clipped the accelerometer and an autopilot's height estimate
diverged."""


def build_sitl_world(
    scene: SceneConfig,
    seed: int,
    image_size_px: int,
    physics_hz: float,
    wind: WindConfig,
    start_offset: StartPose | None,
) -> World:
    """The world with the drone landed below the start pose (or at the default start), rotors stopped."""
    camera = CameraConfig(width=image_size_px, height=image_size_px)
    world = World(
        WorldConfig(scene=scene, camera=camera, drone=SITL_QUAD, physics_hz=physics_hz, wind=wind),
        seed=seed,
    )
    if start_offset is not None:
        o = start_offset
        position, yaw_enu = world.scene.pose_for_offset(o.right_m, o.up_m, o.distance_m, o.yaw_deg)
        world.drone.set_pose((float(position[0]), float(position[1]), world.drone.resting_height_m), yaw_enu)
    world.drone.stop_rotors()
    return world


def quaternion_wxyz(rotation: np.ndarray) -> list[float]:
    """A rotation matrix as a unit quaternion (w, x, y, z), MAVLink's order."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    if q[0] < 0.0:
        q = [-v for v in q]
    return [float(v) for v in q]


class TruthReader:
    """The world's state as `Truth` (NED from `origin_enu_m`, body FRD), once per sensor period.

    The acceleration is the velocity's change since the previous read over `period_s` (read once
    per period, as the bridges do): exact for the physics step, contacts included.
    """

    def __init__(self, world: World, origin_enu_m: np.ndarray, period_s: float) -> None:
        self.world, self.origin_enu_m, self.period_s = world, origin_enu_m, period_s
        self._velocity_ned = enu_to_ned(world.state().velocity_enu_m_s)

    def read(self) -> Truth:
        """Once per physics frame of a bridge, so the frame changes are written out as what they are: ENU to
        NED swaps east and north and turns up into down; FLU to FRD turns left into right and up into down."""
        world = self.world
        state = world.state()
        px, py, pz = state.position_enu_m.tolist()
        vx, vy, vz = state.velocity_enu_m_s.tolist()
        rx, ry, rz = state.angular_velocity_flu_rad_s.tolist()
        velocity = np.array((vy, vx, -vz))
        acceleration = (velocity - self._velocity_ned) / self.period_s
        self._velocity_ned = velocity
        m = p.getMatrixFromQuaternion(state.quaternion_xyzw.tolist())  # body FLU to ENU, row by row
        o = self.origin_enu_m
        return Truth(
            time_s=world.time_s,
            position_ned_m=np.array((py - o[1], px - o[0], -(pz - o[2]))),
            velocity_ned_m_s=velocity,
            acceleration_ned_m_s2=acceleration,
            rotation_ned_frd=np.array(((m[3], -m[4], -m[5]), (m[0], -m[1], -m[2]), (-m[6], m[7], m[8]))),
            rates_frd_rad_s=np.array((rx, -ry, -rz)),
        )


class CameraClock:
    """What a bridge needs of a camera: take the pose for a frame (the video feed's `capture`) every
    1/fps of simulated time."""

    def __init__(self, capture: Callable[[], None], fps: float) -> None:
        self._capture, self._period = capture, 1.0 / fps
        self._next_s = 0.0
        self.frames = 0

    def restart(self) -> None:
        """A new world's clock (from 0): the next tick captures."""
        self._next_s = 0.0

    def tick(self, sim_s: float) -> None:
        if sim_s + 1e-9 >= self._next_s:
            self._capture()
            self.frames += 1
            self._next_s = max(self._next_s + self._period, sim_s)


BETWEEN_S = 0.02
"""How often (wall) a bridge's lockstep loop lets its caller in between two ticks."""


class LockstepPace:
    """A lockstep that waits for its client too, as the sim-vehicle's does at speed "max".

    An autopilot in lockstep waits for its bridge, so at speed "max" the simulation runs as fast as the
    two can go, whatever the client does: while a controller reads a frame, detects and plans (tens of
    milliseconds of wall time), the vehicle flew on for as many tenths of a simulated second, and a move
    the controller ended on the vehicle's clock ran on by as much. Paced, the world may run `lead_s` of
    simulated time past the moment the client last said it waits on the vehicle's clock (a pace request,
    `drone_inspect_core.launcher_requests`, sent by its vehicle backend's waits), so the vehicle runs
    only while the client waits, flat out.

    Without a client pacing it, the world runs at real time: before the first pace, once the autopilot
    has had `boot_s` of simulated time flat out to boot (its client is still starting: loading its
    models, connecting), and once the client has been silent `silence_s` of wall time (a client that
    stopped must still meet the autopilot's failsafes, and does, in the time they take in the air).
    Flat out there, the world would only spend the CPU its client needs to start or to think."""

    def __init__(
        self, requests: LauncherRequests, lead_s: float = 0.1, silence_s: float = 0.25, boot_s: float = 0.0
    ) -> None:
        self.requests, self.lead_s, self.silence_s, self.boot_s = requests, lead_s, silence_s, boot_s
        self._seen = 0
        self._until_s = 0.0
        self._real_time_from: tuple[float, float] | None = None  # (world s, wall s) where it began

    def holds(self, world_time_s: float) -> bool:
        """Whether the world, at `world_time_s`, must wait (for the client, or for the wall clock)
        before its next tick."""
        requests = self.requests
        paces = requests.paces
        if paces == 0:
            return world_time_s >= self.boot_s and self._ahead_of_the_wall(world_time_s)
        if paces != self._seen:
            self._seen, self._until_s = paces, world_time_s + self.lead_s
        if time.monotonic() - requests.paced_at > self.silence_s:
            return self._ahead_of_the_wall(world_time_s)
        self._real_time_from = None
        return world_time_s >= self._until_s

    def _ahead_of_the_wall(self, world_time_s: float) -> bool:
        """Real time: whether the world ran further than the wall clock since real time began (a new
        world, whose clock starts again, begins it again)."""
        now = time.monotonic()
        start = self._real_time_from
        if start is None or world_time_s < start[0]:
            self._real_time_from = start = (world_time_s, now)
        return world_time_s - start[0] > now - start[1]

    def wait(self, timeout_s: float = 0.005) -> None:
        """Until the client paces again (or `timeout_s`)."""
        self.requests.paced.wait(timeout_s)
        self.requests.paced.clear()


def run_lockstep(
    world_now: Callable[[], World],
    tick: Callable[[], None],
    stop: threading.Event,
    speed: float | None,
    max_sim_s: float | None = None,
    between: Callable[[], None] | None = None,
    on_wall_s: Callable[[float], None] | None = None,
    pace: LockstepPace | None = None,
) -> None:
    """A bridge's loop around its one-tick `tick()`: until `stop`, or `max_sim_s` of the world's time;
    `between()` every `BETWEEN_S` of wall time (a warm simulator's resets: a new world, `world_now()`,
    counts from its own start); with `pace`, a tick waits while the client holds the world; with a
    finite `speed`, sleep until the wall clock catches up (× speed); `on_wall_s(seconds)` after every
    tick, the wall time since the loop (or the world) began."""
    wall0 = next_between = time.monotonic()
    sim0 = world_now().time_s
    while not stop.is_set():
        if max_sim_s is not None and world_now().time_s - sim0 >= max_sim_s:
            break
        if between is not None and time.monotonic() >= next_between:
            world = world_now()
            between()
            next_between = time.monotonic() + BETWEEN_S
            if world_now() is not world:
                sim0, wall0 = world_now().time_s, time.monotonic()
        if pace is not None and pace.holds(world_now().time_s):
            pace.wait()
            continue
        tick()
        if speed is not None:
            ahead_s = (world_now().time_s - sim0) / speed - (time.monotonic() - wall0)
            if ahead_s > 0.001:
                time.sleep(ahead_s)
        if on_wall_s is not None:
            on_wall_s(time.monotonic() - wall0)


def continue_in(
    world: World,
    origin_enu_m: np.ndarray,
    period_s: float,
    last_seen: Truth | None,
    next_time_s: float,
    camera: CameraClock | None,
) -> tuple[TruthReader, AutopilotFrame]:
    """A bridge's truth reader for `world` (a fresh build, the drone landed, rotors stopped) and the
    frame that shows it to the autopilot as the continuation of `last_seen` at `next_time_s`
    (`AutopilotFrame.continuing`); the camera's clock starts again with the world's."""
    if last_seen is None:
        raise RuntimeError("a bridge can rebase only after its autopilot was told something")
    reader = TruthReader(world, origin_enu_m, period_s)
    frame = AutopilotFrame.continuing(last_seen, reader.read(), next_time_s)
    world.drone.stop_rotors()
    if camera is not None:
        camera.restart()
    return reader, frame
