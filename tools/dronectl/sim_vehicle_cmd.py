"""`dronectl sim-vehicle`: the simulated drone as a PX4-flavoured MAVLink vehicle (+ MJPEG video).

Ports follow PX4 SITL for instance N: binds UDP 14580+N, sends to 127.0.0.1:14540+N
(connect MAVSDK with `udpin://0.0.0.0:14540`), video at http://127.0.0.1:8080+N/stream.mjpg.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from drone_inspect_core.signing import SigningKey
from drone_inspect_core.sim_speed import SimSpeed, parse_sim_speed
from drone_inspect_core.world_options import StartPose
from dronectl.options import CommandParser, seed_value
from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config
from sim_world.vehicle.commander import CommanderConfig
from sim_world.vehicle.config import SimVehicleConfig
from sim_world.vehicle.params import ParamError, checked_overrides, parse_param_overrides
from sim_world.vehicle.serve import SimVehicleRun, serve


def _speed(text: str) -> SimSpeed:
    try:
        return parse_sim_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parser() -> argparse.ArgumentParser:
    ap = CommandParser(prog="dronectl sim-vehicle", description=__doc__)
    net = ap.add_argument_group("MAVLink and video")
    net.add_argument(
        "--instance", type=int, default=0, help="PX4 SITL instance number: shifts every port by N"
    )
    net.add_argument("--bind", default="127.0.0.1", help="address to bind (default loopback)")
    net.add_argument("--local-port", type=int, help="UDP port the vehicle listens on (default 14580+N)")
    net.add_argument("--remote-host", default="127.0.0.1", help="where telemetry goes (default 127.0.0.1)")
    net.add_argument("--remote-port", type=int, help="UDP port telemetry goes to (default 14540+N)")
    net.add_argument("--sysid", type=int, help="MAVLink system id (default 1+N, as PX4 SITL)")
    net.add_argument("--video-port", type=int, help="MJPEG HTTP port (default 8080+N)")
    net.add_argument("--video-fps", type=float, default=15.0, help="camera frames per second (default 15)")
    net.add_argument("--no-video", action="store_true", help="serve no camera (saves the rendering CPU)")
    net.add_argument(
        "--signing-key",
        metavar="FILE",
        help="MAVLink 2 signing: sign everything and obey only messages signed with this key (32 bytes, "
        "64 hex digits or base64 on one line); fly it with `--signing-key FILE` too",
    )
    sim = ap.add_argument_group("simulation")
    sim.add_argument(
        "--speed",
        type=_speed,
        default=1.0,
        help="simulated seconds per wall second (0.05..100, default 1), or 'max': physics as fast as "
        "it steps; above 1 the setpoint-loss and preflight-disarm timers also count wall time",
    )
    sim.add_argument("--scene", type=Path, help="scene YAML file (default: the built-in scene)")
    sim.add_argument("--seed", type=seed_value, default=0, help="scene seed (default 0)")
    sim.add_argument("--size", type=int, default=224, help="camera image size in pixels (default 224)")
    sim.add_argument(
        "--start-offset",
        help="right,up,distance,yaw: start landed below this pose in front of the target; "
        "MIS_TAKEOFF_ALT is set so a takeoff climbs to it",
    )
    sim.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE", help="PX4 parameter at boot"
    )
    sim.add_argument(
        "--boot-delay", type=float, default=2.5, help="arming refused this long after boot (PX4: 2.5 s)"
    )
    sim.add_argument("--duration", type=float, help="exit after this many wall seconds")
    sim.add_argument(
        "--status-every", type=float, default=10.0, help="log loop statistics this often (0: off)"
    )
    return ap


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    try:
        vehicle = SimVehicleConfig(
            instance=args.instance,
            bind_host=args.bind,
            remote_host=args.remote_host,
            remote_port=args.remote_port,
            local_port=args.local_port,
            sysid=args.sysid,
            speed=args.speed,
            commander=CommanderConfig(arming_boot_delay_s=args.boot_delay),
            params=checked_overrides(parse_param_overrides(args.param)),
            video=not args.no_video,
            video_port=args.video_port,
            video_host=args.bind,
            video_fps=args.video_fps,
            signing_key=None if args.signing_key is None else SigningKey.load(args.signing_key),
        )
        run = SimVehicleRun(
            vehicle=vehicle,
            scene=DEFAULT_SCENE if args.scene is None else load_scene_config(args.scene),
            seed=args.seed,
            start_offset=StartPose.parse(args.start_offset) if args.start_offset else None,
            image_size_px=args.size,
            duration_s=args.duration,
            status_every_s=args.status_every,
        )
    except (ValueError, ParamError, SceneConfigError) as exc:
        print(f"dronectl sim-vehicle: {exc}", file=sys.stderr)
        return 2
    return serve(run, sys.stdout)
