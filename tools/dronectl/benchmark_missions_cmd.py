"""`dronectl benchmark-missions`: randomised centring missions from unseen scenes, planners side by side.

    dronectl benchmark-missions --n 200 --seed 1 --json runs/bench_missions.json
    dronectl benchmark-missions --n 20 --seed 1 --vehicle sim-mavlink --planner latent --parallel 2
    dronectl benchmark-missions --n 50 --targets 3 --twins --absent 0.2 --instructions heldout
    dronectl benchmark-missions --n 100 --seed 1 --targets 3 --planner latent --instructions-per-flight 3

Prints success rate, mean steps, mean steps over the oracle's, final offset, the
loop's boundary refinement moves, loop overhead and wrong-target centrings (the loop
stopped on another target, per truth; in-process sim only) per planner, and with
--absent how many absent-target missions ended target_not_found and how many moved,
with --instructions-per-flight N (flights of N instructions, one take-off) how many instructions were
centred, on the wrong target and not found, by place in the flight; --json writes the same plus every
mission's row.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from controller.benchmarks.missions import BenchmarkConfig, format_summary, run_benchmark
from controller.missions.schema import FaultSpec, Mission, load_mission, parse_mission
from controller.planning.planners import PLANNER_NAMES
from drone_inspect_core.files import OutputDirError, write_json_atomic
from drone_inspect_core.parallel import RayUnavailableError, add_ray_option
from drone_inspect_core.sim_speed import parse_sim_speed
from dronectl.ardupilot_options import add_ardupilot_options, resolve_ardupilot_dir
from dronectl.options import CommandParser, at_least, new_file, seed_value
from sim_world.ardupilot_bridge.ardupilot_process import ArduPilotFolderError
from sim_world.px4_bridge.px4_process import Px4FolderError, find_px4_dir


def faults_from_args(args: argparse.Namespace) -> dict[str, Any] | None:
    """The `faults:` mapping of a mission for the fault options given (None when none is)."""
    link = {
        "loss": args.link_loss, "latency_ms": args.link_latency_ms, "jitter_ms": args.link_jitter_ms,
        "duplicate": args.link_duplicate, "reorder": args.link_reorder,
    }  # fmt: skip
    camera = {
        "drop": args.frame_drop, "freeze_at_s": args.camera_freeze_at_s,
        "freeze_for_s": args.camera_freeze_for_s, "dies_at_s": args.camera_dies_at_s,
    }  # fmt: skip
    faults: dict[str, Any] = {}
    if any(link.values()):
        faults["link"] = link
    if camera["drop"] or camera["freeze_at_s"] is not None or camera["dies_at_s"] is not None:
        faults["camera"] = camera
    if args.gust_m_s:
        faults["gust_m_s"] = args.gust_m_s
    if args.vehicle_dies_at_s is not None:
        faults["vehicle_dies_at_s"] = args.vehicle_dies_at_s
    if faults:
        FaultSpec.model_validate(faults)  # a bad value is named now, not in every mission
    return faults or None


def base_mission(args: argparse.Namespace) -> Mission:
    """The mission every benchmark mission copies: `--mission FILE` (or the default), with the options
    given on the command line over it; a missing PX4 folder is named before anything flies."""
    given = {"vehicle": args.vehicle} if args.vehicle is not None else {}
    for option, field in (
        ("checkpoint", "checkpoint"), ("max_steps", "max_steps"), ("epsilon_px", "epsilon_px"),
        ("detector", "detector"), ("detector_checkpoint", "detector_checkpoint"), ("targets", "targets"),
        ("kind", "target_kind"),
    ):  # fmt: skip
        if getattr(args, option) is not None:
            given[field] = getattr(args, option)
    if args.twins:
        given["twins"] = True
    loop = {"scale_moves": False} if args.fixed_moves else {}
    if args.second_choices is not None:
        loop["max_second_choices"] = args.second_choices
    faults = faults_from_args(args)
    if args.mission is not None:
        base = load_mission(args.mission)
        data = {**base.model_dump(mode="json", exclude_unset=True), "name": "benchmark"}
        source = f"--mission {args.mission} with the command line's options"
    else:
        data, source = {"name": "benchmark", "tags": ["benchmark"]}, "the command line's options"
    data.update(given)
    if loop:
        data["loop"] = {**data.get("loop", {}), **loop}
    if faults:
        data["faults"] = faults
    vehicle = data.get("vehicle", "sim")
    if vehicle == "sim-mavlink" and args.sim_speed is not None:
        data["sim_speed"] = _speed("--sim-speed", args.sim_speed)
    if vehicle == "px4-sitl":
        px4 = {"speed": _speed("--px4-speed", args.px4_speed or "max"), "keep_ulog": False}
        folder = args.px4 or data.get("px4", {}).get("dir")
        data["px4"] = {**data.get("px4", {}), **px4, "dir": str(find_px4_dir(folder))}
    if vehicle == "ardupilot-sitl":
        ardupilot = {"speed": _speed("--ardupilot-speed", args.ardupilot_speed or "max"), "keep_logs": False}
        folder = args.ardupilot or data.get("ardupilot", {}).get("dir")
        data["ardupilot"] = {**data.get("ardupilot", {}), **ardupilot, "dir": resolve_ardupilot_dir(folder)}
    return parse_mission(data, source)


def number_range(text: str) -> tuple[float, float]:
    """`LO,HI` as two numbers, LO <= HI."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO,HI (two numbers), got {text!r}") from None
    if not lo <= hi:
        raise argparse.ArgumentTypeError(f"expected LO <= HI, got {text!r}")
    return lo, hi


def _speed(option: str, text: str) -> float | str:
    try:
        return parse_sim_speed(text)
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def build_parser(prog: str = "dronectl benchmark-missions", description: str | None = None) -> CommandParser:
    """The options of `benchmark-missions` (also what `dronectl bench missions` flies each way)."""
    parser = CommandParser(prog=prog, description=description or __doc__.splitlines()[0])
    parser.add_argument(
        "--n", type=at_least(1), default=200, help="missions per planner (default: %(default)s)"
    )
    parser.add_argument(
        "--seed", type=seed_value, default=0, help="benchmark seed: picks the scenes and starts"
    )
    parser.add_argument(
        "--planner",
        default=",".join(PLANNER_NAMES),
        help="comma-separated planners (default: %(default)s)",
    )
    parser.add_argument(
        "--mission",
        type=Path,
        help="the base mission every benchmark mission copies (scene family, kinds, vehicle, loop, "
        "faults, ...); its scene seed, start, planner and instruction are drawn per mission; the options "
        "below change it (default: the default mission)",
    )
    parser.add_argument(
        "--vehicle",
        choices=("sim", "sim-mavlink", "px4-sitl", "ardupilot-sitl"),
        help="in-process (default), the sim-vehicle over MAVLink, or real PX4 / ArduPilot SITL flying "
        "the world",
    )
    parser.add_argument("--px4", help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument("--px4-speed", help="px4-sitl: simulation speed, a factor or 'max' (default: max)")
    add_ardupilot_options(parser, speed_default="max")
    parser.add_argument(
        "--sim-speed",
        help="sim-mavlink: the sim-vehicle's speed, a factor (1 = real time, the default) or 'max'",
    )
    parser.add_argument("--checkpoint", help="latent planner checkpoint folder (default: the shipped one)")
    parser.add_argument("--max-steps", type=at_least(1), help="step budget per mission (default: 20)")
    parser.add_argument("--epsilon-px", type=float, help="ε in pixels (default: 10 at 224 px)")
    parser.add_argument(
        "--kind", help="the named target's kind in every mission (default: drawn from the scene family)"
    )
    parser.add_argument(
        "--detector", choices=("image", "truth"), help="truth: isolate the planners (sim only; default image)"
    )
    parser.add_argument("--detector-checkpoint", help="image detector run folder (default: the shipped one)")
    parser.add_argument(
        "--fixed-moves", action="store_true", help="the paper's fixed move lengths instead of scaled ones"
    )
    parser.add_argument(
        "--second-choices",
        type=int,
        default=None,
        help="moves per mission on the planner's best-ranked move after a 'no move' far from centre "
        "(default: the loop's 4; 0: such a 'no move' is a stall, the planner alone)",
    )
    parser.add_argument(
        "--scene-seed",
        type=seed_value,
        default=None,
        help="fly every mission in this one scene of the family (a site, e.g. the one a collection was "
        "flown in), from starts drawn per mission (default: an unseen scene per mission)",
    )
    for option, default in (("view-fraction", "0.1,0.85"), ("distance-m", "1.5,3.0"), ("yaw-deg", "-10,10")):
        parser.add_argument(
            f"--{option}",
            type=number_range,
            default=None,
            metavar="LO,HI",
            help=f"the random starts' {option.replace('-', ' ')} range (default {default})",
        )
    parser.add_argument("--targets", type=int, help="targets in every scene, the named one included (1..4)")
    parser.add_argument(
        "--twins", action="store_true", help="one other target of the named kind, in another trim colour"
    )
    parser.add_argument(
        "--instructions",
        metavar="train|heldout|FILE.yaml",
        help="the phrases naming the target: the planner's train or heldout phrases, or an operator-words "
        "file (docs/operator_words.yaml's format), flown as the loop understands them (default: heldout "
        "with --targets/--twins/--absent, else 'center the <kind>')",
    )
    parser.add_argument(
        "--absent",
        type=float,
        default=0.0,
        help="fraction of missions whose instruction names a target not in the scene "
        "(they must end target_not_found)",
    )
    parser.add_argument(
        "--instructions-per-flight",
        type=at_least(1),
        default=1,
        help="flights of N instructions, one take-off: each names another of the scene's targets "
        "(needs --targets N or more; default 1)",
    )
    faults = parser.add_argument_group("injected faults (sim-mavlink and the SITL vehicles; gusts also sim)")
    faults.add_argument(
        "--link-loss", type=float, default=0.0, help="fraction of MAVLink datagrams lost, each way"
    )
    faults.add_argument("--link-latency-ms", type=float, default=0.0, help="added one-way latency, ms")
    faults.add_argument(
        "--link-jitter-ms", type=float, default=0.0, help="± uniform jitter on that latency, ms"
    )
    faults.add_argument("--link-duplicate", type=float, default=0.0, help="fraction of datagrams sent twice")
    faults.add_argument(
        "--link-reorder", type=float, default=0.0, help="fraction held back behind later ones"
    )
    faults.add_argument("--frame-drop", type=float, default=0.0, help="fraction of camera frames never sent")
    faults.add_argument("--camera-freeze-at-s", type=float, help="the picture freezes at this simulated time")
    faults.add_argument("--camera-freeze-for-s", type=float, default=3.0, help="for this long (default 3 s)")
    faults.add_argument("--camera-dies-at-s", type=float, help="the video stream dies at this simulated time")
    faults.add_argument(
        "--gust-m-s", type=float, default=0.0, help="wind gusts, standard deviation per axis, m/s"
    )
    faults.add_argument("--vehicle-dies-at-s", type=float, help="the vehicle (or PX4) is killed at this time")
    parser.add_argument(
        "--parallel",
        type=at_least(1),
        default=1,
        help="worker processes, or the local Ray's CPUs (default: 1)",
    )
    add_ray_option(parser)
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="sim-mavlink: a fresh simulator for every mission (default: each worker keeps one warm and "
        "resets it to the next mission's world)",
    )
    parser.add_argument("--json", type=new_file, help="write the summary and every mission's row here")
    parser.add_argument(
        "--report", type=Path, help="keep each mission's report.json under this folder (new or empty)"
    )
    parser.add_argument(
        "--rerun",
        action="store_true",
        help="with --report: record each mission for the Rerun viewer as <report>/<mission>/mission.rrd",
    )
    return parser


def benchmark_config(args: argparse.Namespace, parser: CommandParser) -> BenchmarkConfig | None:
    """The benchmark the options ask for; None (said on stderr) when a SITL folder is missing, a bad
    option is a usage error (exit 2)."""
    try:
        return BenchmarkConfig(
            base=base_mission(args),
            n=args.n, seed=args.seed, planners=tuple(p.strip() for p in args.planner.split(",") if p.strip()),
            parallel=args.parallel, rerun=args.rerun, ray=args.ray, instructions=args.instructions,
            absent=args.absent, instructions_per_flight=args.instructions_per_flight,
            scene_seed=args.scene_seed, warm=not args.fresh,
            **{field: getattr(args, field) for field in ("view_fraction", "distance_m", "yaw_deg")
               if getattr(args, field) is not None},
        )  # fmt: skip
    except (Px4FolderError, ArduPilotFolderError) as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return None
    except ValueError as exc:
        parser.error(str(exc))


def main(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.rerun:
        if args.report is None:
            parser.error("--rerun needs --report (the folder that keeps each mission's recording)")
        try:
            import rerun  # noqa: F401
        except ImportError:
            print(
                "dronectl benchmark-missions: --rerun needs the Rerun SDK: pip install -e '.[rerun]'",
                file=sys.stderr,
            )
            return 2
    logging.getLogger().setLevel(logging.WARNING)
    config = benchmark_config(args, parser)
    if config is None:
        return 2
    try:
        summary = run_benchmark(config, report_dir=args.report)
    except OutputDirError as exc:
        print(f"dronectl benchmark-missions: --report {exc}", file=sys.stderr)
        return 2
    except RayUnavailableError as exc:
        print(f"dronectl benchmark-missions: {exc}", file=sys.stderr)
        return 2
    print(format_summary(summary))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, summary, indent=1)
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
