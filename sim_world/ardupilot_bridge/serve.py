"""The ArduPilot simulator as a process: its config as JSON, and `serve` (signals, parent watch, ready line).

`python -m sim_world.ardupilot_bridge --config FILE.json` (what the `ardupilot-sitl` mission kit and
`dronectl bench ardupilot` start) and `dronectl ardupilot-sim` (a person's terminal) both end in `serve`.
"""

from __future__ import annotations

import logging
from dataclasses import asdict
from pathlib import Path
from typing import Any, TextIO

from sim_world.ardupilot_bridge.ardupilot_process import ArduPilotStartError
from sim_world.ardupilot_bridge.bridge import ArduPilotRestartedError, JsonTiming
from sim_world.ardupilot_bridge.link import ArduPilotSilentError, PhysicsLinkError
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig, run_ardupilot_sim
from sim_world.physics.wind import WindConfig
from sim_world.process_entry import say_ready, stop_on_signals
from sim_world.process_entry import watch_parent as parent_watch
from sim_world.px4_bridge.geodesy import HomePoint
from sim_world.rendering.video import VideoError, VideoFaults
from sim_world.scene.config import parse_scene_config
from sim_world.sitl.imu import SensorNoise
from sim_world.vehicle.serve import StartPose

log = logging.getLogger(__name__)

READY_PREFIX = "ardupilot-sim ready: "


def config_to_json(config: ArduPilotSimConfig) -> dict[str, Any]:
    """The config as JSON, for the simulator's process entry point."""
    return {
        "ardupilot_dir": str(config.ardupilot_dir),
        "instance": config.instance,
        "scene": config.scene.model_dump(mode="json"),
        "seed": config.seed,
        "start_offset": None if config.start_offset is None else asdict(config.start_offset),
        "image_size_px": config.image_size_px,
        "camera": config.camera,
        "video_port": config.video_port,
        "video_host": config.video_host,
        "mavlink_port": config.mavlink_port,
        "timing": asdict(config.timing),
        "home": asdict(config.home),
        "noise": asdict(config.noise),
        "system_id": config.system_id,
        "params": dict(config.params),
        "log_dir": None if config.log_dir is None else str(config.log_dir),
        "connect_timeout_s": config.connect_timeout_s,
        "duration_s": config.duration_s,
        "wind": asdict(config.wind),
        "video_faults": None if config.video_faults is None else asdict(config.video_faults),
        "ardupilot_dies_at_s": config.ardupilot_dies_at_s,
    }


def config_from_json(data: dict[str, Any]) -> ArduPilotSimConfig:
    """The inverse of `config_to_json` (values are validated by the dataclasses and the scene model)."""
    return ArduPilotSimConfig(
        ardupilot_dir=Path(data["ardupilot_dir"]),
        instance=int(data["instance"]),
        scene=parse_scene_config(data["scene"], "<ardupilot-sim config>"),
        seed=int(data["seed"]),
        start_offset=None if data["start_offset"] is None else StartPose(**data["start_offset"]),
        image_size_px=int(data["image_size_px"]),
        camera=bool(data["camera"]),
        video_port=data["video_port"],
        video_host=data["video_host"],
        mavlink_port=data["mavlink_port"],
        timing=JsonTiming(**data["timing"]),
        home=HomePoint(**data["home"]),
        noise=SensorNoise(**data["noise"]),
        system_id=data["system_id"],
        params={str(k): float(v) for k, v in data["params"].items()},
        log_dir=None if data["log_dir"] is None else Path(data["log_dir"]),
        connect_timeout_s=float(data["connect_timeout_s"]),
        duration_s=data["duration_s"],
        wind=WindConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in data["wind"].items()}),
        video_faults=None if data.get("video_faults") is None else VideoFaults(**data["video_faults"]),
        ardupilot_dies_at_s=data.get("ardupilot_dies_at_s"),
    )


def serve(config: ArduPilotSimConfig, out: TextIO, watch_parent: bool = False) -> int:
    """Run until SIGINT, SIGTERM, SIGHUP (or the parent's death, with `watch_parent`); an exit code.

    Prints one line `ardupilot-sim ready: {json}` to `out` once ArduPilot's first physics frame is
    answered (URLs, ArduPilot's system id), and a summary at the end. 0: stopped as asked; 1: ArduPilot
    or the simulator failed (the reason is logged and printed).
    """
    stop = stop_on_signals("ardupilot-sim")
    if watch_parent:
        parent_watch(stop, "ardupilot-sim")
    try:
        stats = run_ardupilot_sim(config, stop, on_ready=lambda info: say_ready(out, READY_PREFIX, info))
    except (ArduPilotStartError, ArduPilotSilentError, ArduPilotRestartedError, PhysicsLinkError, VideoError,
            OSError) as exc:  # fmt: skip
        log.error("ardupilot-sim: %s", exc)
        out.write(f"ardupilot-sim failed: {exc}\n")
        out.flush()
        return 1
    out.write(
        f"ardupilot-sim: {stats.sim_s:.1f} s simulated in {stats.wall_s:.1f} s "
        f"(x{stats.real_time_factor:.2f}), "
        f"{stats.frames} physics frames, {stats.repeats} repeated, {stats.camera_frames} camera frames\n"
    )
    out.flush()
    return 0
