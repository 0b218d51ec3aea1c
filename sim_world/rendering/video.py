"""The forward camera as MJPEG, rendered in its own process.

PyBullet holds the GIL while it renders (12 ms per 224 px frame on an idle core of
this machine, 40+ ms when loaded), so rendering inside the vehicle loop stalled
command acks and telemetry. As PX4 SITL leaves the camera to its simulator process,
the vehicle leaves it to a render process: that process rebuilds the same scene
from the same config and seed, and for each frame poses its drone as the vehicle's
drone was last seen (a shared array the vehicle loop overwrites after each physics
batch), renders, and publishes image + truth through `sim_world.rendering.mjpeg.MjpegServer`.

The truth (target pixel centre/bbox, drone pose) is for the test harness only,
via `/truth.json`; nothing of it goes over MAVLink.
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
import os
import random
import signal
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import pybullet as p

from drone_inspect_core.frames import enu_to_ned, yaw_enu_to_ned_rad
from drone_inspect_core.world_options import CameraFaults
from sim_world.rendering.mjpeg import MjpegServer
from sim_world.world import World, WorldConfig

log = logging.getLogger(__name__)

# Shared pose layout: position ENU (3), quaternion xyzw (4), velocity ENU (3), sim time.
_POSE_LEN = 11
POSE_LOCK_TIMEOUT_S = 0.05
IDLE_POLL_S = 0.005
"""How often the render process looks at its stop flag, its commands and the drone's pose (its truth's
extremes) while it renders nothing; a demand for a picture or a truth wakes it at once."""


class VideoError(RuntimeError):
    """The render process could not start or serve (port in use, scene error, ...)."""


class TruthExtremes:
    """The largest speeds and excursions from home over every frame's pose (judging only)."""

    def __init__(self) -> None:
        self.horizontal_speed_m_s = 0.0
        self.vertical_speed_m_s = 0.0
        self.low_ned_m = [0.0, 0.0, 0.0]
        self.high_ned_m = [0.0, 0.0, 0.0]

    def update(self, ned_m: list[float], velocity_ned_m_s: list[float]) -> None:
        vn, ve, vd = velocity_ned_m_s
        self.horizontal_speed_m_s = max(self.horizontal_speed_m_s, math.hypot(vn, ve))
        self.vertical_speed_m_s = max(self.vertical_speed_m_s, abs(vd))
        self.low_ned_m = [min(a, b) for a, b in zip(self.low_ned_m, ned_m, strict=True)]
        self.high_ned_m = [max(a, b) for a, b in zip(self.high_ned_m, ned_m, strict=True)]

    def as_dict(self) -> dict[str, Any]:
        return {
            "max_horizontal_speed_m_s": round(self.horizontal_speed_m_s, 3),
            "max_vertical_speed_m_s": round(self.vertical_speed_m_s, 3),
            "min_ned_m": [round(v, 3) for v in self.low_ned_m],
            "max_ned_m": [round(v, 3) for v in self.high_ned_m],
        }


@dataclass(frozen=True)
class VideoConfig:
    host: str = "127.0.0.1"
    port: int = 8080
    fps: float = 15.0
    jpeg_quality: int = 85
    start_timeout_s: float = 60.0  # a fresh interpreter importing pybullet and building the scene
    clock: str = "wall"
    """Where the poses come from: "wall", the vehicle loop's after each physics batch (sim-vehicle);
    "sim", the caller's `capture()` `fps` times per simulated second (the bridges, in lockstep, faster
    or slower than real time). Either way the latest pose is rendered `fps` times per wall second: a
    stream's reader gets `fps` fresh frames a second on its own clock, as from a camera, however fast
    the simulation runs or while it stands still (a lockstep waiting for its client), and the
    simulation never waits for a render."""
    faults: CameraFaults | None = None

    def __post_init__(self) -> None:
        if self.clock not in ("wall", "sim"):
            raise ValueError(f"VideoConfig.clock must be 'wall' or 'sim', got {self.clock!r}")


class WorldVideoFeed:
    """Vehicle-side handle of the render process; `capture()` from the vehicle loop only."""

    def __init__(self, world: World, origin_enu_m: np.ndarray, config: VideoConfig):
        self._world = world
        self.config = config
        ctx = mp.get_context("spawn")  # no fork of a process that holds a PyBullet client and threads
        self._pose = ctx.Array("d", _POSE_LEN)
        # Lock-free shared flags and counters (one writer each): a render process killed while it
        # held a lock, or while it slept in a multiprocessing Event's wait(), would hang the vehicle
        # on its next set() or read (Event.set() waits for every sleeper to wake; a dead one never
        # does: sim-vehicle hung on a process-group SIGTERM). Only the pose keeps a lock, taken by
        # the vehicle with a timeout.
        self._frames = ctx.Value("q", 0, lock=False)
        self._render_s = ctx.Value("d", 0.0, lock=False)
        self._stop = ctx.Value("b", 0, lock=False)
        self._conn, self._child_conn = ctx.Pipe(duplex=False)
        self._child_commands, self._commands = ctx.Pipe(duplex=False)  # child reads: a new world to show
        self._write_pose()
        self._proc = ctx.Process(
            target=_serve,
            args=(world.config, world.seed, np.asarray(origin_enu_m, float), config, self._pose, self._stop),
            kwargs={
                "conn": self._child_conn,
                "commands": self._child_commands,
                "frames": self._frames,
                "render_s": self._render_s,
            },
            name="sim-vehicle-video",
            daemon=True,
        )
        self.stream_url = ""
        self.resets_built_ahead = 0  # resets whose world the render process had built ahead (`prepare`)

    @property
    def truth_url(self) -> str:
        return self.stream_url.replace("/stream.mjpg", "/truth.json")

    @property
    def frames(self) -> int:
        return int(self._frames.value)

    @property
    def mean_render_ms(self) -> float:
        n = self.frames
        return 1000.0 * self._render_s.value / n if n else 0.0

    def start(self) -> None:
        """Spawn the render process and wait until it serves; VideoError naming the port otherwise."""
        self._proc.start()
        self._child_conn.close()  # the child's ends live in the child now
        self._child_commands.close()
        if not self._conn.poll(self.config.start_timeout_s):
            self.close()
            raise VideoError(f"video process did not start within {self.config.start_timeout_s:.0f} s")
        kind, detail = self._conn.recv()
        if kind != "ready":
            self.close()
            raise VideoError(f"video on {self.config.host}:{self.config.port}: {detail}")
        self.stream_url = detail
        log.info("video %s (render process %d)", self.stream_url, self._proc.pid)

    def prepare(self, world_config: WorldConfig, seed: int) -> None:
        """A reset to this world is coming: the render process builds it now, while the caller builds its
        own, and `reset` with the same world takes it (any other world is built then, as without this)."""
        if self._proc.is_alive():
            self._commands.send(("build", world_config, seed))

    def reset(self, world: World, origin_enu_m: np.ndarray, faults: CameraFaults | None) -> None:
        """Show `world` (a fresh build, of any scene and seed) from now on, its truth from `origin_enu_m`
        with `faults`: the render process rebuilds it, and its first frame is published before this
        returns (so no frame of the old world comes after). `VideoError` if it cannot."""
        if not self._proc.is_alive():
            raise VideoError("the render process has ended: it cannot show a new world")
        self._world = world
        self._write_pose()
        self._commands.send(("reset", world.config, world.seed, np.asarray(origin_enu_m, float), faults))
        while True:
            if not self._conn.poll(self.config.start_timeout_s):
                raise VideoError(f"the render process did not show the new world within "
                                 f"{self.config.start_timeout_s:.0f} s")  # fmt: skip
            kind, detail = self._conn.recv()
            if kind == "reset":
                self.resets_built_ahead += bool(detail)
                log.info("video: the new world is shown (%s)", "built ahead" if detail else "built on reset")
                return
            if kind == "reset-error":
                raise VideoError(f"the render process cannot show the new world: {detail}")

    def capture(self) -> None:
        """Hand the drone's current pose to the render process (cheap: no rendering, no waiting here);
        its next frame shows it (see `VideoConfig.clock`)."""
        self._write_pose()

    def _write_pose(self) -> bool:
        s = self._world.state()
        values = [*s.position_enu_m, *s.quaternion_xyzw, *s.velocity_enu_m_s, self._world.time_s]
        lock = self._pose.get_lock()
        if not lock.acquire(timeout=POSE_LOCK_TIMEOUT_S):  # the renderer died holding it: skip
            log.debug("video pose lock not free within %.2f s; frame pose not updated", POSE_LOCK_TIMEOUT_S)
            return False
        try:
            self._pose[:] = values
        finally:
            lock.release()
        return True

    @property
    def alive(self) -> bool:
        return self._proc.is_alive()

    def close(self, timeout_s: float = 5.0) -> None:
        self._stop.value = 1  # a plain shared byte: safe even if the render process is already dead
        if self._proc.pid is not None:
            self._proc.join(timeout_s)
            if self._proc.is_alive():
                log.warning("video process did not stop; terminating it")
                self._proc.terminate()
                self._proc.join(timeout_s)
        self._conn.close()
        self._commands.close()


class _Scene:
    """What the render process shows: the world, its truth's origin and the injected camera faults."""

    def __init__(self, world: World, origin_enu_m: np.ndarray, faults: CameraFaults | None) -> None:
        self.world, self.origin_enu_m = world, origin_enu_m
        self.faults = faults or CameraFaults()
        self.rng = random.Random(self.faults.seed)
        self.extremes = TruthExtremes()
        self.frozen: tuple[np.ndarray, float] | None = None  # the picture a freeze shows, and its stamp
        self.renders = 0
        self._drawn: tuple[list[float], np.ndarray, dict[str, Any]] | None = None  # pose, picture, truth
        self._noted: list[float] | None = None  # the last pose the extremes saw
        self._published: list[float] | None = None  # the pose of the latest frame published

    def note(self, values: list[float]) -> None:
        """The drone's pose now (the shared pose): the truth's extremes see every pose read, drawn or not."""
        if values != self._noted:
            self._noted = values
            position_ned_m, velocity_ned_m_s = _drone_ned(values, self.origin_enu_m)
            self.extremes.update(position_ned_m.tolist(), velocity_ned_m_s.tolist())

    def dead(self, values: list[float]) -> bool:
        """Whether the injected fault has the stream die by the pose's simulated time (and says so)."""
        dies_at_s = self.faults.dies_at_s
        if dies_at_s is None or values[10] < dies_at_s:
            return False
        log.warning("video: the stream dies at %.1f s (injected fault)", values[10])
        return True

    def moved(self, values: list[float]) -> bool:
        """Whether the pose differs from the latest published frame's (whose truth is then not of now)."""
        return values != self._published

    def draw(self, values: list[float], read_s: float, server: MjpegServer, answers: int = 0) -> bool:
        """Render the drone at `values` (the shared pose, read at `read_s`: the frame's scene stamp) and
        publish it with its truth (faults applied), answering the server's demands up to `answers`; False
        once the injected fault says the stream dies.

        A pose the last frame showed (the same position, attitude and simulated time: a lockstep that
        stands still while its client reads and plans) is not drawn again: the picture drawn for it is
        published with fresh camera noise, as a camera gives each frame of a scene that stands still."""
        world = self.world
        self.note(values)
        if self._drawn is None or self._drawn[0] != values:
            p.resetBasePositionAndOrientation(
                world.drone.body_id, values[0:3], values[3:7], physicsClientId=world.client_id
            )
            render = world.render(with_seg=True, noise=False)
            truth = frame_truth(world, render, values, self.origin_enu_m)
            self._drawn = (list(values), render.rgb, truth)
            self.renders += 1
        _, clean, truth = self._drawn
        sim_s, faults = values[10], self.faults
        if self.dead(values):
            return False
        image, scene_s = world.add_noise(clean), read_s
        if faults.freeze_at_s is not None and 0 <= sim_s - faults.freeze_at_s < faults.freeze_for_s:
            self.frozen = (image, scene_s) if self.frozen is None else self.frozen
            image, scene_s = self.frozen  # a frozen camera's picture is of the moment it froze
        if not (faults.drop and self.rng.random() < faults.drop):
            server.publish(image, {**truth, "extremes": self.extremes.as_dict()}, scene_s, answers)
            self._published = self._drawn[0]
        return True


def _read_pose(pose: Any) -> tuple[list[float], float]:
    """The shared pose, and the time.monotonic() it was read at: the scene it describes was current then
    (the vehicle overwrites it after each physics batch, the bridges at each capture)."""
    with pose.get_lock():
        return list(pose), time.monotonic()


def _serve(
    world_config: WorldConfig,
    seed: int,
    origin_enu_m: np.ndarray,
    config: VideoConfig,
    pose: Any,
    stop: Any,
    conn: Connection,
    commands: Connection,
    frames: Any,
    render_s: Any,
) -> None:
    """The render process: same scene, drone posed from `pose`, frames at `config.fps` (see `clock`);
    a new world when the vehicle sends one (`WorldVideoFeed.reset`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent stops us
    try:
        scene = _Scene(World(world_config, seed), origin_enu_m, config.faults)
    except Exception as exc:
        conn.send(("error", f"cannot build the world: {exc}"))
        return
    try:
        try:
            server = MjpegServer(config.host, config.port, jpeg_quality=config.jpeg_quality, on_demand=True)
        except OSError as exc:
            conn.send(("error", str(exc)))
            return
        with server:
            conn.send(("ready", server.stream_url))
            period = 1.0 / config.fps
            next_t = time.monotonic()
            parent = os.getppid()
            # A vehicle killed outright never sets `stop` (and `daemon=True` only acts on a normal
            # exit): re-parenting means it is gone, so stop rather than render for nobody forever.
            pending = _PendingWorld()
            while not stop.value and os.getppid() == parent:
                if commands.poll():
                    command = commands.recv()
                    if command[0] == "build":  # a reset is coming: its world is built meanwhile
                        pending.build(command[1], command[2])
                        continue
                    scene = _reset(scene, command, pending, pose, server, conn)
                    next_t = time.monotonic()
                asked, new_frame = server.asked()  # before the pose: a scene read after every demand
                values, read_s = _read_pose(pose)
                scene.note(values)
                if scene.dead(values):
                    break
                clients = server.stream_clients
                streaming = clients > 0 and time.monotonic() >= next_t
                if not (streaming or new_frame or (asked and scene.moved(values))):
                    if asked:
                        server.answer(asked)  # the truth asked for is the latest frame's
                    left = max(0.0, next_t - time.monotonic()) if clients else IDLE_POLL_S
                    server.wait_asked(min(IDLE_POLL_S, left))  # a demand wakes it at once
                    continue
                t0 = time.monotonic()
                if not scene.draw(values, read_s, server=server, answers=asked):
                    break
                render_s.value += time.monotonic() - t0
                frames.value += 1
                next_t = max(next_t + period, time.monotonic())  # streams: at most `fps` frames a wall second
    finally:
        scene.world.close()
        pending.close()


class _PendingWorld:
    """The world a coming reset will show, built ahead (`WorldVideoFeed.prepare`) while the vehicle builds
    its own; a reset of another world (or seed) builds its own and this one is closed."""

    def __init__(self) -> None:
        self.key: tuple[WorldConfig, int] | None = None
        self.world: World | None = None
        self.error: Exception | None = None

    def build(self, world_config: WorldConfig, seed: int) -> None:
        self.close()
        self.key = (world_config, seed)
        try:
            self.world = World(world_config, seed)
        except Exception as exc:  # said when the reset comes for it
            self.error = exc

    def take(self, world_config: WorldConfig, seed: int) -> World | None:
        """The world built ahead if it is this one (a build that failed raises its error); else None."""
        if self.key != (world_config, seed):
            self.close()
            return None
        world, error = self.world, self.error
        self.key, self.world, self.error = None, None, None
        if error is not None:
            raise error
        return world

    def close(self) -> None:
        if self.world is not None:
            self.world.close()
        self.key, self.world, self.error = None, None, None


def _reset(
    scene: _Scene,
    command: tuple[Any, ...],
    pending: _PendingWorld,
    pose: Any,
    server: MjpegServer,
    conn: Connection,
) -> _Scene:
    """Build the world a reset asks for (or take the one built ahead) and publish its first frame; the old
    scene stays on error."""
    _, world_config, seed, origin_enu_m, faults = command
    world: World | None = None
    try:
        world = pending.take(world_config, seed)
        ahead = world is not None
        world = world if world is not None else World(world_config, seed)
        fresh = _Scene(world, origin_enu_m, faults)
    except Exception as exc:
        if world is not None:
            world.close()
        conn.send(("reset-error", f"cannot build the world: {exc}"))
        return scene
    scene.world.close()
    fresh.draw(*_read_pose(pose), server=server)
    conn.send(("reset", ahead))
    return fresh


def _drone_ned(pose: list[float], origin_enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shared pose's position from home and velocity, in NED."""
    return enu_to_ned(np.asarray(pose[0:3]) - origin_enu_m), enu_to_ned(pose[7:10])


def frame_truth(world: World, render: Any, pose: list[float], origin_enu_m: np.ndarray) -> dict[str, Any]:
    """JSON-able truth of one frame: the target in pixels and the drone's pose (ENU and NED from home)."""
    everyone = world.targets_truth(render)  # in the order of scene.targets: the named one first
    truth = everyone[world.scene.named_index]
    position = np.asarray(pose[0:3])
    position_ned_m, velocity_ned_m_s = _drone_ned(pose, origin_enu_m)
    yaw_enu = world.state().yaw_enu_rad
    return {
        "time_s": round(pose[10], 4),
        "targets": [  # every target of the scene, the named one first (wrong-target judging)
            {
                "kind": target.kind,
                "attribute": target.attribute,
                "offset_px": _floats(t.offset_px),
                "in_view": bool(t.in_view),
            }
            for target, t in zip(world.scene.targets, everyone, strict=True)
        ],
        "target": {
            "kind": world.scene.target_kind,
            "centre_px": _floats(truth.centre_px),
            "offset_px": _floats(truth.offset_px),
            "bbox_px": None if truth.bbox_px is None else _floats(truth.bbox_px),
            "in_view": bool(truth.in_view),
            "fully_in_view": bool(truth.fully_in_view),
            "visible_fraction": float(truth.visible_fraction),
            "depth_m": _finite(truth.depth_m),
            "image_size": [int(v) for v in truth.image_size],
        },
        "drone": {
            "position_enu_m": _floats(position),
            "position_ned_m": _floats(position_ned_m),
            "velocity_ned_m_s": _floats(velocity_ned_m_s),
            "yaw_deg": math.degrees(yaw_enu_to_ned_rad(yaw_enu)),
        },
    }


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _floats(values: Any) -> list[float | None]:
    return [_finite(float(v)) for v in values]
