"""`dronectl sim-vehicle`: build the PyBullet world and serve it as a MAVLink vehicle until stopped.

The drone starts landed. With a start offset (right, up, distance, yaw relative to the
centred pose in front of the target, as `Scene.pose_for_offset`) it starts on the
floor below that pose with that heading, and MIS_TAKEOFF_ALT is set so that a
plain takeoff climbs exactly to the pose (an explicit MIS_TAKEOFF_ALT override wins).
A hovering start is not offered: PX4 boots on the ground, so must the sim.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, TextIO

from drone_inspect_core.config_files import from_json
from drone_inspect_core.launcher_requests import reset_config
from drone_inspect_core.signing import SigningKey
from drone_inspect_core.world_options import CameraFaults, StartPose, WindConfig
from sim_world.process_entry import LauncherRequests, say_ready, stop_on_signals
from sim_world.process_entry import watch_parent as parent_watch
from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.video import VideoConfig, VideoError, WorldVideoFeed
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import PX4_PARAMS
from sim_world.vehicle.server import LoopStats, SimVehicle, SimVehicleError
from sim_world.vehicle.world_model import WorldVehicleModel
from sim_world.world import World, WorldConfig

log = logging.getLogger(__name__)

_TAKEOFF_SPEC = next(s for s in PX4_PARAMS if s.name == "MIS_TAKEOFF_ALT")


@dataclass(frozen=True)
class SimVehicleRun:
    """Everything `dronectl sim-vehicle` needs: the vehicle, the world and how long to run."""

    vehicle: SimVehicleConfig = field(default_factory=SimVehicleConfig)
    scene: SceneConfig = DEFAULT_SCENE
    seed: int = 0
    start_offset: StartPose | None = None
    image_size_px: int = 224
    duration_s: float | None = None  # None: until stopped
    status_every_s: float = 0.0  # log the loop statistics this often (0: never)
    wind: WindConfig = field(default_factory=WindConfig)
    video_faults: CameraFaults | None = None
    dies_at_s: float | None = None
    """An injected fault: the vehicle process kills itself (SIGKILL) at this simulated time."""

    def __post_init__(self) -> None:
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0 (or none: until stopped), got {self.duration_s}")
        if not 32 <= self.image_size_px <= 1024:
            raise ValueError(f"image_size_px must be in [32, 1024], got {self.image_size_px}")
        if not self.status_every_s >= 0:
            raise ValueError(f"status_every_s must be >= 0, got {self.status_every_s}")


@dataclass(frozen=True)
class SimVehicleReady:
    """What the ready line says: where to connect, and the vehicle's MAVLink system id."""

    mavlink_url: str
    system_id: int
    local_address: list[Any]
    video_url: str | None
    truth_url: str | None
    vehicle_time_s: float | None = None
    """After a reset: the vehicle's clock (its `time_boot_ms`, in s) when the new world began; telemetry
    stamped later is the new world's."""


def world_config_of(run: SimVehicleRun) -> WorldConfig:
    """The world a run flies in (its scene, camera and wind; the seed is the run's)."""
    camera = CameraConfig(width=run.image_size_px, height=run.image_size_px)
    return WorldConfig(scene=run.scene, camera=camera, wind=run.wind)


def build_world(run: SimVehicleRun) -> tuple[World, SimVehicleConfig]:
    """The world with the drone placed, and the vehicle config with MIS_TAKEOFF_ALT filled in."""
    world = World(world_config_of(run), seed=run.seed)
    vehicle = run.vehicle
    if run.start_offset is not None:
        o = run.start_offset
        position, yaw_enu = world.scene.pose_for_offset(o.right_m, o.up_m, o.distance_m, o.yaw_deg)
        ground = world.drone.resting_height_m
        world.drone.set_pose((float(position[0]), float(position[1]), ground), yaw_enu)
        climb = min(max(float(position[2]) - ground, _TAKEOFF_SPEC.minimum), _TAKEOFF_SPEC.maximum)
        if "MIS_TAKEOFF_ALT" not in vehicle.params:
            vehicle = replace(vehicle, params={**vehicle.params, "MIS_TAKEOFF_ALT": round(climb, 3)})
        log.info("start below %s (ENU), takeoff climbs %.2f m", [round(float(v), 2) for v in position], climb)
    return world, vehicle


def run_sim_vehicle(
    run: SimVehicleRun,
    stop: threading.Event | None = None,
    on_ready: Callable[[SimVehicle], None] | None = None,
    on_end: Callable[[SimVehicle], None] | None = None,
    requests: LauncherRequests | None = None,
    on_reset: Callable[[SimVehicle, str | None], None] | None = None,
) -> LoopStats:
    """Serve the world until `stop` is set or `duration_s` passes; returns the loop statistics.

    `on_ready(vehicle)` is called once the ports are open, `on_end(vehicle)` before it closes.
    `requests`: the launcher's (`drone_inspect_core.launcher_requests`); a reset puts a new world behind
    the running vehicle (`SimVehicle.reset`, the video feed's `reset`), then `on_reset(vehicle, None)`,
    or `on_reset(vehicle, why)` when it could not (the old world flies on).
    """
    stop = stop or threading.Event()
    world, vehicle_config = build_world(run)
    try:
        model = WorldVehicleModel(world)
        video = None
        if vehicle_config.video:
            video = WorldVideoFeed(
                world,
                model.origin_enu_m,
                VideoConfig(
                    vehicle_config.video_host,
                    vehicle_config.http_video_port,
                    vehicle_config.video_fps,
                    faults=run.video_faults,
                ),
            )
        with SimVehicle(model, vehicle_config, video=video) as vehicle:
            if on_ready is not None:
                on_ready(vehicle)
            waited = 0.0
            period = run.status_every_s if run.status_every_s > 0 else 0.5
            if run.dies_at_s is not None or requests is not None:
                period = min(period, 0.02 if requests is not None else 0.05)
            while not stop.is_set() and vehicle.running:
                if run.duration_s is not None and waited >= run.duration_s:
                    break
                if run.dies_at_s is not None and vehicle.stats().sim_s >= run.dies_at_s:
                    log.warning(
                        "sim-vehicle: dying at %.1f s of simulated time (injected fault)", run.dies_at_s
                    )
                    os.kill(os.getpid(), signal.SIGKILL)  # no goodbye on the link, as a crash
                step = period if run.duration_s is None else min(period, run.duration_s - waited)
                began = time.monotonic()
                if requests is not None:
                    requests.wait(step)  # a reset request wakes it at once
                else:
                    stop.wait(step)
                waited += time.monotonic() - began
                request = requests.take() if requests is not None else None
                if request is not None:
                    run, world = _reset(vehicle, video, run, world, request, on_reset)
                if run.status_every_s > 0:
                    s = vehicle.stats()
                    log.info(
                        "sim %.1f s / wall %.1f s (x%.2f), %s, %d frames (%.1f ms), %d msgs in, %d out",
                        s.sim_s, s.wall_s, s.real_time_factor, vehicle.mode.name, s.video_frames,
                        s.mean_render_ms, s.messages_in, s.messages_out,
                    )  # fmt: skip
            stats = vehicle.stats()
            if on_end is not None:
                on_end(vehicle)
    finally:
        world.close()
    return stats


def _reset(
    vehicle: SimVehicle,
    video: WorldVideoFeed | None,
    run: SimVehicleRun,
    world: World,
    request: dict[str, Any],
    on_reset: Callable[[SimVehicle, str | None], None] | None,
) -> tuple[SimVehicleRun, World]:
    """The new world a reset request asks for, behind the running vehicle; the old run and world when it
    cannot be (said through `on_reset`)."""
    try:
        config = reset_config(request)
        if config is None:
            raise ValueError(f"not a request this vehicle knows: {sorted(request)}")
        new_run = run_from_json(config)
        new_run = replace(new_run, vehicle=replace(new_run.vehicle, signing_key=run.vehicle.signing_key))
        if replace(new_run.vehicle, params=run.vehicle.params) != run.vehicle:
            raise ValueError("a reset may change the world, not the vehicle (ports, id, speed, limits)")
        if new_run.image_size_px != run.image_size_px:
            raise ValueError("a reset may not change the camera's image size")
        if video is not None:  # the render process builds its world while this one is built
            video.prepare(world_config_of(new_run), new_run.seed)
        new_world, vehicle_config = build_world(new_run)
    except (ValueError, KeyError, TypeError) as exc:
        if on_reset is not None:
            on_reset(vehicle, f"bad reset request: {exc}")
        return run, world
    model = WorldVehicleModel(new_world)

    def show_it() -> None:
        if video is not None:
            video.reset(new_world, model.origin_enu_m, new_run.video_faults)

    try:
        vehicle.reset(model, vehicle_config, show_it)
    except (SimVehicleError, VideoError) as exc:
        new_world.close()
        if on_reset is not None:
            on_reset(vehicle, str(exc))
        raise  # a vehicle half reset cannot fly on: the process ends, and its launcher sees why
    world.close()
    if on_reset is not None:
        on_reset(vehicle, None)
    return new_run, new_world


# --------------------------------------------------------------------------- serving a process
READY_PREFIX = "sim-vehicle ready: "
RESET_PREFIX = "sim-vehicle reset: "
"""A warm vehicle's answer to a reset: the ready facts for the new world, or `{"error": ...}`."""
SUMMARY_PREFIX = "sim-vehicle link: "
"""The last line of a served vehicle: who its link accepted messages from and what it dropped."""


def link_summary(vehicle: SimVehicle) -> dict[str, Any]:
    """What the vehicle's link let through and kept out, and the parameters changed since boot."""
    stats = vehicle.stats()
    return {
        "signed": vehicle.config.signing_key is not None,
        "accepted": stats.messages_in,
        "accepted_from": vehicle.senders(),
        "dropped_unsigned": stats.messages_unsigned,
        "dropped_foreign": stats.messages_foreign,
        "dropped_bad": stats.messages_bad,
        "params_changed": vehicle.params.changed(),
    }


def serve(
    run: SimVehicleRun,
    out: TextIO,
    watch_parent: bool = False,
    extra_stop: threading.Event | None = None,
    requests: LauncherRequests | None = None,
) -> int:
    """Serve until SIGINT, SIGTERM, SIGHUP (or the parent's death, with `watch_parent`); an exit code.

    Prints `sim-vehicle ready: {json}` once the ports are open (`SimVehicleReady`) and a summary
    at the end. 0: stopped as asked; 1: the vehicle could not start or failed (a port in use, a
    bad scene): the reason is printed, and nothing keeps running.
    """
    stop = extra_stop or stop_on_signals("sim-vehicle")
    if watch_parent:
        parent_watch(stop, "sim-vehicle")

    def info(vehicle: SimVehicle) -> SimVehicleReady:
        cfg = vehicle.config
        return SimVehicleReady(
            mavlink_url=cfg.connection_url(),
            system_id=cfg.system_id,
            local_address=list(vehicle.local_address),
            video_url=vehicle.video_url,
            truth_url=vehicle.truth_url,
        )

    def reset(vehicle: SimVehicle, error: str | None) -> None:
        answer = replace(info(vehicle), vehicle_time_s=vehicle.reset_clock_s) if error is None else None
        say_ready(out, RESET_PREFIX, answer if answer is not None else {"error": error})

    def end(vehicle: SimVehicle) -> None:
        say_ready(out, SUMMARY_PREFIX, link_summary(vehicle))

    try:
        stats = run_sim_vehicle(
            run, stop, lambda v: say_ready(out, READY_PREFIX, info(v)), end, requests, reset
        )
    except (OSError, SimVehicleError, VideoError) as exc:
        print(f"sim-vehicle failed: {exc}", file=sys.stderr, flush=True)  # a launcher reads both
        return 1
    out.write(
        f"sim-vehicle: {stats.sim_s:.1f} s simulated in {stats.wall_s:.1f} s "
        f"(x{stats.real_time_factor:.2f} real time), {stats.video_frames} video frames\n"
    )
    out.flush()
    return 0


def secret_json(run: SimVehicleRun) -> dict[str, Any]:
    """What the run's JSON (`config_files.to_json`, also kept beside the run's report) leaves out, for the
    child's stdin only: the signing key (hex), if any."""
    key = run.vehicle.signing_key
    return {} if key is None else {"signing_key": key.hex()}


def run_from_json(data: dict[str, Any]) -> SimVehicleRun:
    """The run from its JSON merged with `secret_json` (validated by the dataclasses and the scene model)."""
    data = dict(data)
    key = data.pop("signing_key", None)
    run = from_json(SimVehicleRun, data)
    if key is None:
        return run
    return replace(run, vehicle=replace(run.vehicle, signing_key=SigningKey.from_text(str(key))))
