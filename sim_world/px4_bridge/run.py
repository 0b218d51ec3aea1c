"""`run_px4_sim`: the world, its camera, the bridge and PX4 SITL together, until stopped.

Order matters: the simulator port is bound first (a port in use fails before PX4 or
anything else starts), then the render process, then PX4, which dials the port. The
bridge waits for PX4's connection (watching that PX4 is still alive), runs until
PX4 answers in lockstep, says it is ready, and then runs until `stop` is set or PX4
goes away. Everything is closed in reverse order on every way out.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TextIO

from drone_inspect_core.ports import (
    PX4_OFFBOARD_REMOTE_UDP,
    PX4_SIMULATOR_TCP,
    SIM_VEHICLE_VIDEO_HTTP,
    free_port,
)
from drone_inspect_core.world_options import CameraFaults, StartPose, WindConfig
from sim_world.process_entry import LauncherRequests, say_ready, stop_on_signals
from sim_world.process_entry import watch_parent as parent_watch
from sim_world.px4_bridge.bridge import BridgeStats, BridgeTiming, CameraClock, Px4Bridge
from sim_world.px4_bridge.geodesy import HomePoint, magnetic_field_ned_gauss
from sim_world.px4_bridge.link import (
    Px4DisconnectedError,
    SimulatorLinkError,
    SimulatorServer,
)
from sim_world.px4_bridge.messages import px4_airframe_params
from sim_world.px4_bridge.px4_process import (
    MAX_INSTANCE,
    Px4Options,
    Px4Ports,
    Px4Process,
    Px4StartError,
    check_px4_params,
)
from sim_world.px4_bridge.sensors import SensorNoise, SensorSuite
from sim_world.rendering.video import VideoConfig, VideoError, WorldVideoFeed
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.sitl.resets import SitlResets
from sim_world.sitl.rig import SITL_QUAD, LockstepPace, build_sitl_world
from sim_world.world import World, derived_seed

log = logging.getLogger(__name__)

PX4_QUAD = SITL_QUAD
"""The project's quadrotor with compliant landing legs (3 mm static deflection, damped)."""
PHYSICS_HZ = 250.0
"""One physics step per 4 ms sensor tick, as PX4's Gazebo worlds step (`max_step_size` 0.004). Two steps
a tick (500 Hz) flew the same missions (takeoff, loop and landing took the same simulated time), and the
missions benchmark's PX4 way took 28.3-29.7 s then against 26.4-26.7 s (docs/performance.md)."""
MAGNETIC_MODEL_YEAR = 2025.5
MAX_SPEED_FACTOR = 10.0
"""For PX4's timeouts, `--speed max` counts as 10× real time (measured here: 2.7× with the 224 px
camera, 8.9× without, on 2 cores)."""
BOOT_S = 12.0
"""Simulated seconds PX4 runs flat out before its client's first pace (then real time until it paces,
`rig.LockstepPace`): PX4 v1.15.3 here had a global position 2.7 and 7.7 s after it started (two runs)."""


@dataclass(frozen=True)
class Px4SimConfig:
    """One `dronectl px4-sim` (or one `px4-sitl` mission's simulator)."""

    px4_dir: Path
    instance: int = 0
    scene: SceneConfig = DEFAULT_SCENE
    seed: int = 0
    start_offset: StartPose | None = None
    image_size_px: int = 224
    camera: bool = True
    video_port: int | None = None  # None: 8080 + instance
    video_host: str = "127.0.0.1"
    timing: BridgeTiming = field(default_factory=BridgeTiming)
    home: HomePoint = field(default_factory=HomePoint)
    noise: SensorNoise = field(default_factory=SensorNoise)
    system_id: int | None = None  # None: PX4's own (1 + instance)
    params: dict[str, float] = field(default_factory=dict)
    px4_log_dir: Path | None = None  # keep PX4's console output and .ulg logs here
    connect_timeout_s: float = 60.0  # PX4 start to lockstep (a cold start here: ~1 s)
    duration_s: float | None = None  # of simulated time; None: until stopped
    wind: WindConfig = field(default_factory=WindConfig)
    video_faults: CameraFaults | None = None
    px4_dies_at_s: float | None = None
    """An injected fault: PX4 is killed (SIGKILL) at this simulated time."""
    mavlink_remote_port: int | None = None
    """Where PX4's MAVLink link sends (127.0.0.1); None: PX4's own ports for the instance (4560+N,
    14580+N -> 14540+N, ...). Given (a mission: the relay's port), every PX4 port is free per run and
    PX4 runs only that one link (`px4_process.Px4Ports`)."""

    def __post_init__(self) -> None:
        if not 0 <= self.instance <= MAX_INSTANCE:
            raise ValueError(f"PX4 instance must be 0..{MAX_INSTANCE}, got {self.instance}")
        check_px4_params(self.params)
        for name in ("video_port", "mavlink_remote_port"):
            port = getattr(self, name)
            if port is not None and not 0 <= port <= 65535:
                raise ValueError(f"{name} must be a port (0..65535), got {port}")
        if not 32 <= self.image_size_px <= 1024:
            raise ValueError(f"image_size_px must be in [32, 1024], got {self.image_size_px}")
        if self.system_id is not None and not 1 <= self.system_id <= 254:
            raise ValueError(f"system_id must be 1..254, got {self.system_id}")
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0, got {self.duration_s}")

    @property
    def free_ports(self) -> bool:
        """Whether PX4's ports are chosen free for this run (see `mavlink_remote_port`)."""
        return self.mavlink_remote_port is not None

    @property
    def simulator_port(self) -> int:
        """The TCP port the bridge listens on for PX4 (0: any free one)."""
        return 0 if self.free_ports else PX4_SIMULATOR_TCP + self.instance

    @property
    def mavlink_url(self) -> str:
        """Where a MAVSDK client (or the relay) listens for this PX4 (PX4 sends to 127.0.0.1 there)."""
        port = (
            self.mavlink_remote_port
            if self.mavlink_remote_port is not None
            else PX4_OFFBOARD_REMOTE_UDP + self.instance
        )
        return f"udpin://0.0.0.0:{port}"

    @property
    def http_video_port(self) -> int:
        return SIM_VEHICLE_VIDEO_HTTP + self.instance if self.video_port is None else self.video_port


@dataclass(frozen=True)
class Px4SimReady:
    """What `on_ready` learns: the URLs, PX4's system id and the simulator's pid-free facts."""

    mavlink_url: str
    system_id: int
    video_url: str | None
    truth_url: str | None
    px4_pid: int | None
    lockstep_after_s: float
    simulator_tcp: int = 0
    """The bridge's TCP port PX4 dialled."""
    px4_mavlink_udp: int | None = None
    """PX4's one MAVLink port (bound on every interface), where the run chose it."""
    vehicle_time_s: float | None = None
    """After a reset: PX4's clock (its `time_boot`, s) when the new world began."""


def build_px4_world(config: Px4SimConfig) -> World:
    """The world with the drone landed below the start pose (or at the default start)."""
    return build_sitl_world(
        config.scene, config.seed, config.image_size_px, PHYSICS_HZ, config.wind, config.start_offset
    )


def run_px4_sim(
    config: Px4SimConfig,
    stop: threading.Event | None = None,
    on_ready: Callable[[Px4SimReady], None] | None = None,
    requests: LauncherRequests | None = None,
    on_reset: Callable[[Px4SimReady | None, str | None], None] | None = None,
) -> BridgeStats:
    """Serve the world to PX4 until `stop`, `duration_s`, or PX4's exit (`Px4StartError` / disconnect).

    `requests`: the launcher's (`drone_inspect_core.launcher_requests`); a reset puts a new world behind
    the running PX4 (`Px4Bridge.rebase`, the video feed's `reset`), then `on_reset(ready, None)`, or
    `on_reset(None, why)` when it could not (the old world flies on)."""
    stop = stop or threading.Event()
    worlds = SitlResets(config, build_px4_world)  # the world flown now, and the resets that replace it
    world = worlds.world
    with contextlib.closing(worlds):
        origin = world.state().position_enu_m.copy()
        field = magnetic_field_ned_gauss(
            config.home.latitude_deg,
            config.home.longitude_deg,
            config.home.altitude_amsl_m,
            MAGNETIC_MODEL_YEAR,
        )
        sensors = SensorSuite(config.home, field, config.noise, seed=derived_seed(config.seed, 7))
        with SimulatorServer("127.0.0.1", config.simulator_port) as server:
            video = None
            if config.camera:
                video = WorldVideoFeed(
                    world,
                    origin,
                    VideoConfig(
                        config.video_host,
                        config.http_video_port,
                        fps=config.timing.camera_fps,
                        clock="sim",
                        faults=config.video_faults,
                    ),
                )
                video.start()
            try:
                options = Px4Options(
                    px4_dir=config.px4_dir,
                    instance=config.instance,
                    system_id=config.system_id,
                    params={**px4_airframe_params(world.drone.params), **config.params},
                    keep_logs_in=config.px4_log_dir,
                    speed_factor=MAX_SPEED_FACTOR if config.timing.speed is None else config.timing.speed,
                    console_log=None if config.px4_log_dir is None else config.px4_log_dir / "px4.log",
                    ports=_px4_ports(config, server),
                )
                with Px4Process(options) as px4:
                    _accept(server, px4, config.connect_timeout_s)
                    camera = None if video is None else CameraClock(video.capture, config.timing.camera_fps)
                    bridge = Px4Bridge(world, server, sensors, config.home, config.timing, camera, origin)
                    started = time.monotonic()
                    while not bridge.stats().lockstep:
                        if stop.is_set():
                            return bridge.stats()
                        px4.check_alive()
                        if time.monotonic() - started > config.connect_timeout_s:
                            raise Px4StartError(
                                "PX4 connected but never answered in lockstep within "
                                f"{config.connect_timeout_s:.0f} s:\n"
                                f"{px4.output_tail()}"
                            )
                        bridge.step()
                    ready = Px4SimReady(
                        mavlink_url=config.mavlink_url,
                        system_id=config.system_id or config.instance + 1,
                        video_url=None if video is None else video.stream_url,
                        truth_url=None if video is None else video.truth_url,
                        px4_pid=px4.pid,
                        lockstep_after_s=world.time_s,
                        simulator_tcp=server.address[1],
                        px4_mavlink_udp=None if options.ports is None else options.ports.mavlink_udp,
                    )
                    if on_ready is not None:
                        on_ready(ready)
                    if config.px4_dies_at_s is not None:
                        bridge.run(stop, max_sim_s=max(0.0, config.px4_dies_at_s - world.time_s))
                        if not stop.is_set():
                            log.warning(
                                "killing PX4 at %.1f s of simulated time (injected fault)", world.time_s
                            )
                            px4.kill()
                    remaining = (
                        None if config.duration_s is None else max(0.0, config.duration_s - world.time_s)
                    )

                    def between() -> None:
                        assert requests is not None
                        error = worlds.take(requests, bridge, video)
                        if error is not False and on_reset is not None:
                            answer = replace(ready, vehicle_time_s=bridge.rebased_at_s)
                            on_reset(answer if error is None else None, error or None)

                    paced = requests is not None and config.timing.speed is None
                    pace = LockstepPace(requests, boot_s=BOOT_S) if paced and requests is not None else None
                    try:
                        return bridge.run(
                            stop,
                            max_sim_s=remaining,
                            between=None if requests is None else between,
                            pace=pace,
                        )
                    except Px4DisconnectedError as exc:  # what PX4 said last, beside why we gave up
                        raise Px4DisconnectedError(
                            f"{exc}; PX4's console ended with:\n{px4.output_tail()}"
                        ) from exc
            finally:
                if video is not None:
                    video.close()


def _px4_ports(config: Px4SimConfig, server: SimulatorServer) -> Px4Ports | None:
    """PX4's ports for a run that chooses them: the bridge's (already bound) and a free UDP port for its
    link, checked on every interface, where PX4 binds it."""
    if config.mavlink_remote_port is None:
        return None
    return Px4Ports(server.address[1], free_port("udp", "0.0.0.0"), config.mavlink_remote_port)


def _accept(server: SimulatorServer, px4: Px4Process, timeout_s: float) -> None:
    """Wait for PX4 to dial in, failing at once (with its console) if it exits instead."""
    deadline = time.monotonic() + timeout_s
    while True:
        px4.check_alive()
        try:
            server.accept(min(0.5, max(0.0, deadline - time.monotonic())), expect_pid=px4.pid)
            return
        except SimulatorLinkError:
            if time.monotonic() >= deadline:
                raise SimulatorLinkError(
                    f"PX4 did not connect to TCP port {server.address[1]} within {timeout_s:.0f} s; "
                    f"its console ended with:\n{px4.output_tail()}"
                ) from None


# ----------------------------------------------------------------------------- serving a process
READY_PREFIX = "px4-sim ready: "


RESET_PREFIX = "px4-sim reset: "
"""A warm simulator's answer to a reset: the ready facts, or `{"error": ...}`."""


def serve(
    config: Px4SimConfig, out: TextIO, watch_parent: bool = False, requests: LauncherRequests | None = None
) -> int:
    """Run until SIGINT, SIGTERM, SIGHUP (or the parent's death, with `watch_parent`); an exit code.

    Prints one line `px4-sim ready: {json}` to `out` once PX4 answers in lockstep (URLs,
    PX4's system id), and a summary at the end. 0: stopped as asked; 1: PX4 or the
    simulator failed (the reason is logged and printed).
    """
    stop = stop_on_signals("px4-sim")
    if watch_parent:
        parent_watch(stop, "px4-sim")
    try:
        stats = run_px4_sim(
            config,
            stop,
            on_ready=lambda info: say_ready(out, READY_PREFIX, info),
            requests=requests,
            on_reset=lambda info, error: say_ready(
                out, RESET_PREFIX, info if error is None else {"error": error}
            ),
        )
    except (Px4StartError, Px4DisconnectedError, SimulatorLinkError, VideoError, OSError) as exc:
        log.error("px4-sim: %s", exc)
        out.write(f"px4-sim failed: {exc}\n")
        out.flush()
        return 1
    out.write(
        f"px4-sim: {stats.sim_s:.1f} s simulated in {stats.wall_s:.1f} s (x{stats.real_time_factor:.2f}), "
        f"{stats.answers} PX4 answers, {stats.late_answers} late, {stats.camera_frames} camera frames\n"
    )
    out.flush()
    return 0
