"""`dronectl collect --vehicle ...`: fly the paper's collection protocol through the Vehicle interface.

    dronectl collect --vehicle sim-mavlink --kind gauge --goal scene --out data/flown
    dronectl collect --vehicle px4-sitl --kind valve --goal scene --out data/px4 --n-per-sector 40
    dronectl collect --vehicle ardupilot-sitl --kind gauge --goal scene --out data/ardupilot
    dronectl collect --vehicle udpin://0.0.0.0:14540 --camera http://drone:8080/stream.mjpg \\
        --camera-file camera.yaml --kind gauge --goal here --distance-m 2.0 --box-m 0.6 --out data/mine
    dronectl collect --resume --out data/mine --vehicle ... (the same options: goes on where it stopped)

The goal: `here` (the vehicle hovers at the pose that centres the target), `scene` (a simulated vehicle
flies to its scene's centred pose first), or a `goal.json` of an earlier collection. Then goal images
around it, the eight sectors and the centre class inside the box (`--box-m`), empty views, each captured
once settled and labelled from the image (the target's box tracked from the goal image) checked against
the pose geometry; disagreeing captures are flagged and kept out of training. docs/own-target.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from controller.collection.config import SIMULATED, Box3, FlownCollectConfig, Settling, SimOptions
from controller.missions.vehicles import ARDUPILOT_SITL, PX4_SITL
from dronectl.ardupilot_options import add_ardupilot_options, resolve_ardupilot_dir


def _goal_box(text: str) -> tuple[float, float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,w,h in pixels, got {text!r}") from None
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"expected x,y,w,h in pixels, got {text!r}")
    return values  # type: ignore[return-value]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dronectl collect --vehicle",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--vehicle",
        required=True,
        help=f"{', '.join(SIMULATED)} or a MAVLink URL (udpin://0.0.0.0:14540)",
    )
    p.add_argument("--camera", default=None, help="a real vehicle's camera stream URL (simulated: its own)")
    p.add_argument(
        "--camera-file",
        type=Path,
        default=None,
        help="camera intrinsics: width, height and hfov_deg or a matrix",
    )
    p.add_argument(
        "--kind", default="", help="the target's kind (gauge, valve, switchbox, or one --kinds/--scene adds)"
    )
    p.add_argument(
        "--kinds",
        type=Path,
        default=None,
        help="a kinds file adding your own kind: `kinds: {flange: {words: [flange, pipe flange]}}`",
    )
    p.add_argument(
        "--goal",
        default="",
        help="here, scene (simulated vehicles) or a goal.json of an earlier collection",
    )
    p.add_argument(
        "--goal-box",
        type=_goal_box,
        default=None,
        metavar="X,Y,W,H",
        help="the target's box in the goal image, pixels (default: the detector's, for a kind it knows)",
    )
    p.add_argument(
        "--distance-m",
        type=float,
        default=None,
        help="the target's distance from the goal pose (default: the forward rangefinder)",
    )
    p.add_argument(
        "--box-m",
        default="0.8,0.6,0.4",
        help="half sizes of the capture box around the goal: one number or right,up,forward (m)",
    )
    p.add_argument(
        "--fence-m",
        default="1.5,1.2,1.0",
        help="half sizes of the geofence around the goal (the box must fit with 0.25 m to spare)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="the dataset folder: new or empty (with --resume: the one to go on with)",
    )
    p.add_argument(
        "--resume", action="store_true", help="go on with an interrupted flown collection in --out"
    )
    p.add_argument("--n-goal", type=int, default=20, help="goal images around the goal pose (default 20)")
    p.add_argument(
        "--n-per-sector",
        type=int,
        default=20,
        help="captures per sector and for the centre class (default 20)",
    )
    p.add_argument(
        "--n-empty", type=int, default=10, help="views with the target turned out of the image (default 10)"
    )
    p.add_argument("--block-size", type=int, default=9, help="captures per time block (default 9)")
    p.add_argument(
        "--test-every", type=int, default=5, help="every N-th time block is held out as test (default 5)"
    )
    p.add_argument(
        "--epsilon-px", type=float, default=None, help="ε in pixels (default 10 at 224 px, scaled)"
    )
    p.add_argument(
        "--agree-px",
        type=float,
        default=None,
        help="flag a capture whose image and pose offsets differ more (default 10 %% of the width)",
    )
    p.add_argument("--max-speed", type=float, default=0.5, help="speed limit, m/s (default 0.5)")
    p.add_argument(
        "--settle-timeout-s",
        type=float,
        default=12.0,
        help="skip a capture not settled within this (default 12)",
    )
    p.add_argument(
        "--min-altitude-m", type=float, default=0.4, help="no capture pose below this height (default 0.4)"
    )
    p.add_argument(
        "--on-loss",
        choices=("land", "return"),
        default="land",
        help="a lost camera: land, or return to the goal and hold",
    )
    p.add_argument(
        "--loss-wait-s", type=float, default=5.0, help="how long a lost camera is waited for (default 5)"
    )
    p.add_argument("--seed", type=int, default=0, help="the plan's seed (default 0)")
    p.add_argument("--scene", type=Path, default=None, help="simulated: scene config YAML")
    p.add_argument("--scene-seed", type=int, default=0, help="simulated: the scene's seed (default 0)")
    p.add_argument("--sim-speed", default="max", help="sim-mavlink: simulated s per wall s, or max (default)")
    p.add_argument(
        "--px4", type=Path, default=None, help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)"
    )
    p.add_argument("--px4-speed", default="max", help="px4-sitl: simulated s per wall s, or max (default)")
    add_ardupilot_options(p, speed_default="max")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def config_from(args: argparse.Namespace) -> FlownCollectConfig:
    """The options as a checked config (ValueError naming the option)."""
    return FlownCollectConfig(
        out_dir=args.out, vehicle=args.vehicle, camera=args.camera, kind=args.kind, goal=args.goal,
        box=Box3.parse(args.box_m, "--box-m"), fence=Box3.parse(args.fence_m, "--fence-m"),
        goal_box_px=args.goal_box, distance_m=args.distance_m, camera_file=args.camera_file,
        kinds_file=args.kinds,
        n_goal=args.n_goal, n_per_sector=args.n_per_sector, n_empty=args.n_empty, block_size=args.block_size,
        test_every=args.test_every, epsilon_px=args.epsilon_px, agree_px=args.agree_px,
        max_speed_m_s=args.max_speed, settling=Settling(timeout_s=args.settle_timeout_s),
        min_altitude_m=args.min_altitude_m, on_loss=args.on_loss, loss_wait_s=args.loss_wait_s,
        resume=args.resume, seed=args.seed, progress=not args.no_progress,
        sim=SimOptions(scene_file=args.scene, scene_seed=args.scene_seed, sim_speed=args.sim_speed,
                       px4_dir=args.px4, px4_speed=args.px4_speed, ardupilot_dir=args.ardupilot,
                       ardupilot_speed=args.ardupilot_speed),
    )  # fmt: skip


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    from controller.collection.capture import CameraLostError
    from controller.collection.goal import GoalFileError
    from controller.collection.goal_flight import GoalError
    from controller.collection.plan import PlanError
    from controller.collection.run import collect_flown
    from controller.collection.writer import ResumeError
    from controller.missions.schema import MissionFileError
    from drone_inspect_core.config_files import ConfigFileError
    from drone_inspect_core.files import OutputDirError
    from flight.errors import FlightError

    name = "dronectl collect"
    try:
        config = config_from(args)
        if config.vehicle == PX4_SITL:  # a missing autopilot folder is named before anything starts
            from sim_world.px4_bridge.px4_process import find_px4_dir

            find_px4_dir(None if args.px4 is None else str(args.px4))
        if config.vehicle == ARDUPILOT_SITL:
            resolve_ardupilot_dir(args.ardupilot)
        result = collect_flown(config)
    except (ValueError, ConfigFileError, GoalFileError, ResumeError, OutputDirError, MissionFileError) as exc:
        print(f"{name}: {exc}", file=sys.stderr)  # bad input: nothing flew
        return 2
    except (GoalError, PlanError, CameraLostError, FlightError) as exc:
        print(f"{name}: {type(exc).__name__}: {exc}", file=sys.stderr)
        print(
            f"      the captures so far are kept in {args.out} (marked incomplete; --resume goes on)",
            file=sys.stderr,
        )
        return 1
    counts = ", ".join(f"{split} {n}" for split, n in sorted(result.counts.items()))
    tally = result.tally
    rates = tally.rates()
    state = "complete" if result.complete else "INCOMPLETE (--resume goes on)"
    print(
        f"wrote {tally.taken} captures this flight to {result.out_dir} ({state}): {counts}; "
        f"flagged {result.flagged}"
    )
    if tally.skipped:
        print(
            f"      {len(tally.skipped)} captures did not settle and were skipped: "
            f"{', '.join(tally.skipped[:8])}"
        )
    print(
        f"      {tally.wall_s:.0f} s wall, {tally.vehicle_s:.0f} s on the vehicle's clock: "
        f"{rates['images_per_wall_min']} images per wall minute, {rates['images_per_vehicle_min']} per "
        "vehicle minute"
    )
    if result.contact_sheet is not None:
        print(f"      contact sheet: {result.contact_sheet}")
    print(f"      check it: dronectl dataset check {result.out_dir}")
    return 0 if result.complete else 1
