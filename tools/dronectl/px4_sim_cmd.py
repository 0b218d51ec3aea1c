"""`dronectl px4-sim`: real PX4 SITL flying the simulated drone, with its camera as MJPEG.

Starts PX4 SITL from a PX4 SITL build folder (`--px4`, else $PX4_SITL_DIR) in
external-simulator mode (airframe 10016 none_iris, instance N) and serves it the
PyBullet world over PX4's simulator MAVLink API (TCP 4560+N, lockstep). Connect a
MAVSDK client to `udpin://0.0.0.0:14540+N` and a video client to
http://127.0.0.1:8080+N/stream.mjpg. Stop with Ctrl-C (or SIGTERM / SIGHUP): PX4 stops too.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from drone_inspect_core.ports import PortInUseError
from drone_inspect_core.sim_speed import MAX_SPEED, parse_sim_speed
from drone_inspect_core.world_options import StartPose
from dronectl.options import CommandParser, seed_value
from sim_world.px4_bridge.bridge import BridgeTiming
from sim_world.px4_bridge.geodesy import HomePoint
from sim_world.px4_bridge.instances import Px4InstanceBusyError, conventional_ports, px4_instance
from sim_world.px4_bridge.px4_process import MAX_INSTANCE, Px4FolderError, find_px4_dir
from sim_world.px4_bridge.run import Px4SimConfig, serve
from sim_world.px4_bridge.sensors import SensorNoise
from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config
from sim_world.vehicle.params import ParamError, parse_param_overrides


def parse_speed(text: str) -> float | None:
    """`max` (None: lockstep as fast as PX4 and the physics go) or a factor
    (`drone_inspect_core.sim_speed`)."""
    try:
        speed = parse_sim_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return None if speed == MAX_SPEED else float(speed)


def _home(text: str) -> HomePoint:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"home must be LAT,LON,ALT (degrees, degrees, metres), got {text!r}"
        ) from None
    if not (-90.0 < lat < 90.0 and -180.0 <= lon <= 180.0 and -400.0 < alt < 9000.0):
        raise argparse.ArgumentTypeError(f"home {text!r} is not a place on Earth")
    return HomePoint(lat, lon, alt)


def _instance(text: str) -> int | str:
    if text == "auto":
        return text
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 0..{MAX_INSTANCE} or 'auto', got {text!r}") from None
    if not 0 <= value <= MAX_INSTANCE:
        raise argparse.ArgumentTypeError(f"expected 0..{MAX_INSTANCE} or 'auto', got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    ap = CommandParser(prog="dronectl px4-sim", description=__doc__)
    px4 = ap.add_argument_group("PX4")
    px4.add_argument("--px4", type=Path, help="PX4 SITL build folder (default: $PX4_SITL_DIR)")
    px4.add_argument(
        "--instance",
        type=_instance,
        default=0,
        help=f"PX4 instance 0..{MAX_INSTANCE}: ports shift by N (default 0), or 'auto': the lowest one "
        "no other run holds and whose ports are free; the ports are checked before anything starts",
    )
    px4.add_argument("--sysid", type=int, help="PX4's MAVLink system id (default PX4's: 1+N)")
    px4.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="PX4 parameter at boot (repeatable)",
    )
    px4.add_argument("--px4-logs", type=Path, help="keep PX4's console output and .ulg flight logs here")
    sim = ap.add_argument_group("simulation")
    sim.add_argument(
        "--speed",
        type=parse_speed,
        default=1.0,
        help="simulated seconds per wall second, or 'max' (lockstep as fast as it goes); default 1",
    )
    sim.add_argument("--scene", type=Path, help="scene YAML file (default: the built-in scene)")
    sim.add_argument("--seed", type=seed_value, default=0, help="scene seed (default 0)")
    sim.add_argument(
        "--start-offset",
        help="right,up,distance,yaw: start landed below this pose in front of the target",
    )
    sim.add_argument(
        "--home", type=_home, default=HomePoint(), help="LAT,LON,ALT of home (default PX4's Zurich)"
    )
    sim.add_argument(
        "--noise",
        type=float,
        default=1.0,
        help="scale every sensor noise and bias (default 1; 0.1: nearly ideal)",
    )
    sim.add_argument("--duration", type=float, help="stop after this many simulated seconds")
    cam = ap.add_argument_group("camera")
    cam.add_argument(
        "--no-camera", action="store_true", help="no camera and no video (saves the rendering CPU)"
    )
    cam.add_argument("--size", type=int, default=224, help="camera image size in pixels (default 224)")
    cam.add_argument("--video-port", type=int, help="MJPEG HTTP port (default 8080+N)")
    cam.add_argument("--fps", type=float, default=30.0, help="frames per simulated second (default 30)")
    return ap


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    try:  # everything checked before an instance is taken or anything starts
        config = _config(args, 0 if args.instance == "auto" else args.instance)
    except (Px4FolderError, SceneConfigError, ParamError, ValueError) as exc:
        print(f"dronectl px4-sim: {exc}", file=sys.stderr)
        return 2
    try:
        with px4_instance(args.instance, conventional_ports) as instance:
            return serve(replace(config, instance=instance), sys.stdout)
    except (Px4InstanceBusyError, PortInUseError) as exc:
        print(f"dronectl px4-sim: {exc}", file=sys.stderr)
        return 2


def _config(args: argparse.Namespace, instance: int) -> Px4SimConfig:
    px4_dir = find_px4_dir(args.px4)
    if not 0 < args.noise <= 10:
        raise ValueError(
            f"--noise must be in (0, 10], got {args.noise:g} (PX4 rejects perfectly constant sensors)"
        )
    return Px4SimConfig(
        px4_dir=px4_dir,
        instance=instance,
        scene=DEFAULT_SCENE if args.scene is None else load_scene_config(args.scene),
        seed=args.seed,
        start_offset=StartPose.parse(args.start_offset) if args.start_offset else None,
        image_size_px=args.size,
        camera=not args.no_camera,
        video_port=args.video_port,
        timing=BridgeTiming(speed=args.speed, camera_fps=args.fps),
        home=args.home,
        noise=SensorNoise().scaled(args.noise),
        system_id=args.sysid,
        params=parse_param_overrides(args.param),
        px4_log_dir=args.px4_logs,
        duration_s=args.duration,
    )
