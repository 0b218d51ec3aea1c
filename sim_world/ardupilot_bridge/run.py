"""`run_ardupilot_sim`: the world, its camera, the JSON bridge and ArduCopter SITL together, until stopped.

Order matters: the physics port is bound first (a port in use fails before anything else starts),
then the render process, then ArduPilot, which sends its first servo packet about half a second
after it starts. The bridge answers from the first packet on (lockstep from there), says it is
ready, and runs until `stop` is set or ArduPilot goes away. On the way out ArduPilot is stopped
while the bridge still answers its frames (it only handles SIGTERM between frames), then the camera.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from drone_inspect_core.ports import ARDUPILOT_VIDEO_HTTP
from drone_inspect_core.world_options import CameraFaults, StartPose, WindConfig
from sim_world.ardupilot_bridge.ardupilot_process import (
    MAX_INSTANCE,
    ArduPilotOptions,
    ArduPilotProcess,
    ArduPilotStartError,
    default_mavlink_port,
    json_port,
)
from sim_world.ardupilot_bridge.bridge import ArduPilotBridge, JsonBridgeStats, JsonTiming
from sim_world.ardupilot_bridge.link import JsonPhysicsServer
from sim_world.process_entry import LauncherRequests
from sim_world.px4_bridge.geodesy import HomePoint
from sim_world.rendering.video import VideoConfig, WorldVideoFeed
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.sitl.imu import ImuModel, SensorNoise
from sim_world.sitl.resets import SitlResets
from sim_world.sitl.rig import CameraClock, LockstepPace, build_sitl_world
from sim_world.world import World, derived_seed

log = logging.getLogger(__name__)

STOP_SERVING_S = 3.0  # how long the bridge keeps answering while ArduPilot shuts down
BOOT_S = 45.0
"""Simulated seconds ArduPilot runs flat out before its client's first pace (then real time until it
paces, `rig.LockstepPace`): ArduCopter 4.7 here says "EKF3 IMU0 is using GPS" 41.2-41.3 s after it starts."""


@dataclass(frozen=True)
class ArduPilotSimConfig:
    """One `dronectl ardupilot-sim` (or one `ardupilot-sitl` mission's simulator)."""

    ardupilot_dir: Path
    instance: int = 0
    scene: SceneConfig = DEFAULT_SCENE
    seed: int = 0
    start_offset: StartPose | None = None
    image_size_px: int = 224
    camera: bool = True
    video_port: int | None = None  # None: 8090 + instance
    video_host: str = "127.0.0.1"
    mavlink_port: int | None = None  # UDP on 127.0.0.1 ArduPilot sends its MAVLink to; None: 5760 + 10 N
    timing: JsonTiming = field(default_factory=JsonTiming)
    home: HomePoint = field(default_factory=HomePoint)
    noise: SensorNoise = field(default_factory=SensorNoise)
    system_id: int | None = None  # None: ArduPilot's own (1)
    params: dict[str, float] = field(default_factory=dict)
    log_dir: Path | None = None  # keep ArduPilot's console output and .BIN logs here
    connect_timeout_s: float = 30.0  # ArduPilot start to its first physics frame (here: ~0.5 s)
    duration_s: float | None = None  # of simulated time; None: until stopped
    wind: WindConfig = field(default_factory=WindConfig)
    video_faults: CameraFaults | None = None
    ardupilot_dies_at_s: float | None = None
    """An injected fault: ArduPilot is killed (SIGKILL) at this simulated time."""

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= MAX_INSTANCE:
            raise ValueError(f"ArduPilot instance must be 0..{MAX_INSTANCE}, got {self.instance}")
        if not 32 <= self.image_size_px <= 1024:
            raise ValueError(f"image_size_px must be in [32, 1024], got {self.image_size_px}")
        if self.system_id is not None and not 1 <= self.system_id <= 254:
            raise ValueError(f"system_id must be 1..254, got {self.system_id}")
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0, got {self.duration_s}")

    @property
    def json_port(self) -> int:
        return json_port(self.instance)

    @property
    def udp_mavlink_port(self) -> int:
        return default_mavlink_port(self.instance) if self.mavlink_port is None else self.mavlink_port

    @property
    def mavlink_url(self) -> str:
        """Where a client listens for this ArduPilot (it sends to 127.0.0.1 only)."""
        return f"udpin://127.0.0.1:{self.udp_mavlink_port}"

    @property
    def http_video_port(self) -> int:
        return ARDUPILOT_VIDEO_HTTP + self.instance if self.video_port is None else self.video_port


@dataclass(frozen=True)
class ArduPilotSimReady:
    """What `on_ready` learns: the URLs, ArduPilot's system id and pid, when lockstep began."""

    mavlink_url: str
    system_id: int
    video_url: str | None
    truth_url: str | None
    ardupilot_pid: int | None
    first_frame_after_wall_s: float
    frame_rate_hz: int
    vehicle_time_s: float | None = None
    """After a reset: ArduPilot's clock (s) when the new world began."""


def build_ardupilot_world(config: ArduPilotSimConfig) -> World:
    """The world with the drone landed below the start pose (or at the default start)."""
    return build_sitl_world(
        config.scene, config.seed, config.image_size_px, config.timing.frame_rate_hz, config.wind,
        config.start_offset,
    )  # fmt: skip


def run_ardupilot_sim(
    config: ArduPilotSimConfig,
    stop: threading.Event | None = None,
    on_ready: Callable[[ArduPilotSimReady], None] | None = None,
    requests: LauncherRequests | None = None,
    on_reset: Callable[[ArduPilotSimReady | None, str | None], None] | None = None,
) -> JsonBridgeStats:
    """Serve the world to ArduPilot until `stop`, `duration_s`, or ArduPilot's exit (raised).

    `requests`: the launcher's (`drone_inspect_core.launcher_requests`); a reset puts a new world behind
    the running ArduPilot (`ArduPilotBridge.rebase`, the video feed's `reset`), then `on_reset(ready,
    None)`, or `on_reset(None, why)` when it could not (the old world flies on)."""
    stop = stop or threading.Event()
    worlds = SitlResets(config, build_ardupilot_world)  # the world flown now, and the resets that replace it
    world = worlds.world
    with contextlib.closing(worlds):
        origin = world.state().position_enu_m.copy()
        rng = np.random.default_rng(derived_seed(config.seed, 7))
        imu = ImuModel(config.noise, rng, config.timing.frame_period_s)
        with JsonPhysicsServer("127.0.0.1", config.json_port) as server:
            video = None
            if config.camera:
                video = WorldVideoFeed(
                    world, origin,
                    VideoConfig(config.video_host, config.http_video_port, fps=config.timing.camera_fps,
                                clock="sim", faults=config.video_faults),
                )  # fmt: skip
                video.start()
            try:
                camera = None if video is None else CameraClock(video.capture, config.timing.camera_fps)
                bridge = ArduPilotBridge(world, server, imu, config.timing, camera, origin)
                with ArduPilotProcess(_options(config)) as ardupilot:
                    server.expect_pid = ardupilot.pid  # its servo packets, and no one else's
                    facts: list[ArduPilotSimReady] = []  # the ready facts, which a reset answers with too

                    def ready(info: ArduPilotSimReady) -> None:
                        facts.append(info)
                        if on_ready is not None:
                            on_ready(info)

                    def between() -> None:
                        assert requests is not None
                        error = worlds.take(requests, bridge, video)
                        if error is not False and on_reset is not None:
                            answer = replace(facts[0], vehicle_time_s=bridge.rebased_at_s)
                            on_reset(answer if error is None else None, error or None)

                    paced = requests is not None and config.timing.speed is None
                    try:
                        return _serve(
                            config, stop, ready, bridge, ardupilot, video,
                            None if requests is None else between,
                            LockstepPace(requests, boot_s=BOOT_S) if paced and requests is not None else None,
                        )  # fmt: skip
                    finally:
                        _stop_while_serving(bridge, ardupilot)
            finally:
                if video is not None:
                    video.close()


def _options(config: ArduPilotSimConfig) -> ArduPilotOptions:
    h = config.home
    yaw_deg = 0.0 if config.start_offset is None else config.start_offset.yaw_deg
    return ArduPilotOptions(
        ardupilot_dir=config.ardupilot_dir,
        instance=config.instance,
        system_id=config.system_id,
        mavlink_port=config.udp_mavlink_port,
        home=(h.latitude_deg, h.longitude_deg, h.altitude_amsl_m, yaw_deg % 360.0),
        params=config.params,
        keep_logs_in=config.log_dir,
        console_log=None if config.log_dir is None else config.log_dir / "ardupilot.log",
    )


def _serve(
    config: ArduPilotSimConfig,
    stop: threading.Event,
    on_ready: Callable[[ArduPilotSimReady], None] | None,
    bridge: ArduPilotBridge,
    ardupilot: ArduPilotProcess,
    video: WorldVideoFeed | None,
    between: Callable[[], None] | None = None,
    pace: LockstepPace | None = None,
) -> JsonBridgeStats:
    started = time.monotonic()
    while not bridge.serve_one(timeout_s=0.1):  # ArduPilot's first frame: lockstep from here
        if stop.is_set():
            return bridge.stats()
        ardupilot.check_alive()
        if time.monotonic() - started > config.connect_timeout_s:
            raise ArduPilotStartError(
                f"ArduPilot sent no physics frame to UDP port {config.json_port} within "
                f"{config.connect_timeout_s:.0f} s; its console ended with:\n{ardupilot.output_tail()}"
            )
    ready = ArduPilotSimReady(
        mavlink_url=config.mavlink_url,
        system_id=config.system_id or 1,
        video_url=None if video is None else video.stream_url,
        truth_url=None if video is None else video.truth_url,
        ardupilot_pid=ardupilot.pid,
        first_frame_after_wall_s=round(time.monotonic() - started, 3),
        frame_rate_hz=bridge.stats().ardupilot_rate_hz,
    )
    if on_ready is not None:
        on_ready(ready)
    if config.ardupilot_dies_at_s is not None:
        bridge.run(stop, max_sim_s=max(0.0, config.ardupilot_dies_at_s - bridge.world.time_s))
        if not stop.is_set():
            log.warning("killing ArduPilot at %.1f s of simulated time (injected fault)", bridge.world.time_s)
            ardupilot.kill()
    remaining = None if config.duration_s is None else max(0.0, config.duration_s - bridge.world.time_s)
    return bridge.run(stop, max_sim_s=remaining, between=between, pace=pace)


def _stop_while_serving(bridge: ArduPilotBridge, ardupilot: ArduPilotProcess) -> None:
    """SIGTERM to ArduPilot, answering its frames until it exits (it handles signals between frames)."""
    ardupilot.terminate()
    deadline = time.monotonic() + STOP_SERVING_S
    while ardupilot.alive and time.monotonic() < deadline:
        try:
            bridge.serve_one(timeout_s=0.05)
        except (OSError, ConnectionError):
            break
    ardupilot.close(timeout_s=1.0)
