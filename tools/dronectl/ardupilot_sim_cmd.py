"""`dronectl ardupilot-sim`: real ArduCopter SITL flying the simulated drone, with its camera as MJPEG.

Starts ArduCopter SITL from a folder (`--ardupilot`, else $ARDUPILOT_SITL_DIR, else
../shared/ardupilot-sitl beside the checkout) on ArduPilot's JSON interface (UDP 9002+10N, lockstep),
its MAVLink sent to UDP 127.0.0.1:5760+10N only. Connect a client to `udpin://127.0.0.1:5760+10N`
(the GUIDED backend; mission files: `vehicle: udpin://127.0.0.1:5760`) and a video client to
http://127.0.0.1:8090+N/stream.mjpg. Stop with Ctrl-C (or SIGTERM / SIGHUP): ArduPilot stops too.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dronectl.px4_sim_cmd import _home, parse_speed
from sim_world.ardupilot_bridge.ardupilot_process import (
    MAX_INSTANCE,
    ArduPilotFolderError,
    find_ardupilot_dir,
)
from sim_world.ardupilot_bridge.bridge import JsonTiming
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig
from sim_world.ardupilot_bridge.serve import serve
from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config
from sim_world.sitl.imu import SensorNoise
from sim_world.vehicle.params import ParamError, parse_param_overrides
from sim_world.vehicle.serve import StartPose


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="dronectl ardupilot-sim", description=__doc__)
    ardupilot = ap.add_argument_group("ArduPilot")
    ardupilot.add_argument(
        "--ardupilot", type=Path, help="ArduCopter SITL folder (default: $ARDUPILOT_SITL_DIR, ../shared/...)"
    )
    ardupilot.add_argument(
        "--instance", type=int, default=0, help=f"instance 0..{MAX_INSTANCE}: ports shift by 10 N (default 0)"
    )
    ardupilot.add_argument("--sysid", type=int, help="ArduPilot's MAVLink system id (default ArduPilot's: 1)")
    ardupilot.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE", help="ArduPilot parameter at boot"
    )
    ardupilot.add_argument("--mavlink-port", type=int, help="UDP port ArduPilot sends to (default 5760+10N)")
    ardupilot.add_argument("--logs", type=Path, help="keep ArduPilot's console output and .BIN logs here")
    sim = ap.add_argument_group("simulation")
    sim.add_argument(
        "--speed", type=parse_speed, default=1.0,
        help="simulated seconds per wall second, or 'max' (lockstep as fast as it goes); default 1",
    )  # fmt: skip
    sim.add_argument("--scene", type=Path, help="scene YAML file (default: the built-in scene)")
    sim.add_argument("--seed", type=int, default=0, help="scene seed (default 0)")
    sim.add_argument("--start-offset", help="right,up,distance,yaw: start landed below this pose")
    sim.add_argument("--home", type=_home, help="LAT,LON,ALT of home (default: PX4's Zurich, as px4-sim)")
    sim.add_argument("--noise", type=float, default=1.0, help="scale the IMU noise and bias (default 1)")
    sim.add_argument("--duration", type=float, help="stop after this many simulated seconds")
    cam = ap.add_argument_group("camera")
    cam.add_argument("--no-camera", action="store_true", help="no camera and no video (saves rendering)")
    cam.add_argument("--size", type=int, default=224, help="camera image size in pixels (default 224)")
    cam.add_argument("--video-port", type=int, help="MJPEG HTTP port (default 8090+N)")
    cam.add_argument("--fps", type=float, default=30.0, help="frames per simulated second (default 30)")
    cam.add_argument(
        "--idle-fps", type=float, default=2.0,
        help="frames per simulated second while no motor spins (ArduPilot booting or disarmed; default 2)",
    )  # fmt: skip
    return ap


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    try:
        config = ArduPilotSimConfig(
            ardupilot_dir=find_ardupilot_dir(args.ardupilot),
            instance=args.instance,
            scene=DEFAULT_SCENE if args.scene is None else load_scene_config(args.scene),
            seed=args.seed,
            start_offset=StartPose.parse(args.start_offset) if args.start_offset else None,
            image_size_px=args.size,
            camera=not args.no_camera,
            video_port=args.video_port,
            mavlink_port=args.mavlink_port,
            timing=JsonTiming(
                speed=args.speed, camera_fps=args.fps, idle_camera_fps=min(args.idle_fps, args.fps)
            ),
            noise=SensorNoise().scaled(args.noise),
            system_id=args.sysid,
            params=parse_param_overrides(args.param),
            log_dir=args.logs,
            duration_s=args.duration,
            **({} if args.home is None else {"home": args.home}),
        )
    except (ArduPilotFolderError, SceneConfigError, ParamError, ValueError) as exc:
        print(f"dronectl ardupilot-sim: {exc}", file=sys.stderr)
        return 2
    print(
        f"ArduPilot SITL instance {config.instance}: MAVLink {config.mavlink_url}, "
        f"physics UDP 127.0.0.1:{config.json_port}",
        flush=True,
    )
    return serve(config, sys.stdout)
