"""The command-line options of the commands that fly a mission file (`dronectl fly`, `dronectl console`),
written once: the mission, its overrides (validated by the same `Mission` model as the file), the
simulators' folders and speeds, and a real vehicle's signing key.

`add_mission_options(parser, instructions=...)` declares them; `mission_from_args(args)` loads the
mission with them applied (`MissionFileError` or `ValueError`, naming the option's field, if they do not
fit), resolving a PX4 or ArduPilot folder at once so that a bad one is named before anything starts.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from controller.missions.schema import PX4_SITL, Mission, Px4Spec, load_mission
from controller.planning.planners import PLANNER_NAMES
from dronectl.ardupilot_options import add_ardupilot_options, apply_ardupilot_options
from dronectl.options import add_signing_key, at_least, seed_value

DEFAULT_MISSION = Path(__file__).resolve().parents[2] / "missions" / "default.yaml"

MISSION_FIELDS = (
    "planner", "checkpoint", "epsilon_px", "max_steps", "timeout_s", "vehicle", "camera", "sim_speed",
    "target_kind", "targets",
)  # fmt: skip
"""The mission fields an option of the same name changes (`Mission` validates them)."""


def add_mission_options(parser: argparse.ArgumentParser, instructions: bool) -> None:
    """The mission and its overrides; `instructions`: also `--instruction` (repeatable), else the
    instructions come from elsewhere (the console's page) and `args.instruction` is None."""
    parser.add_argument(
        "--mission", type=Path, default=DEFAULT_MISSION, help="mission YAML (default: %(default)s)"
    )
    parser.add_argument("--planner", choices=PLANNER_NAMES, help="override the mission's planner")
    parser.add_argument("--checkpoint", help="latent planner checkpoint folder (default: the shipped one)")
    parser.add_argument("--seed", type=seed_value, help="override the scene seed (and a random start's seed)")
    parser.add_argument("--epsilon-px", type=float, help="override ε, pixels")
    parser.add_argument("--max-steps", type=at_least(1), help="override the step budget (per instruction)")
    parser.add_argument("--timeout-s", type=float, help="override the time budget (per instruction), seconds")
    if instructions:
        parser.add_argument(
            "--instruction",
            action="append",
            metavar="TEXT",
            help="what to centre, e.g. 'centre the red valve'; repeat it to centre several in one flight "
            "(replaces the mission's instructions)",
        )
    else:
        parser.set_defaults(instruction=None)
    parser.add_argument(
        "--target-kind", help="simulated scenes: the named target's kind (gauge, valve, switchbox, ...)"
    )
    parser.add_argument(
        "--targets", type=int, help="simulated scenes: targets on the wall, the named one included (1..4)"
    )
    parser.add_argument(
        "--vehicle", help="override the vehicle: sim, sim-mavlink, px4-sitl, ardupilot-sitl or a MAVLink URL"
    )
    parser.add_argument("--px4", type=Path, help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument(
        "--px4-speed",
        help="px4-sitl: simulated seconds per wall second, or 'max' (default: the mission's, 1)",
    )
    add_ardupilot_options(parser)
    parser.add_argument(
        "--sim-speed",
        help="sim-mavlink: the sim-vehicle's simulated seconds per wall second, or 'max' (default: the "
        "mission's, 1)",
    )
    parser.add_argument("--camera", help="override the camera: sim or a stream URL")
    add_signing_key(parser)


def mission_from_args(args: argparse.Namespace) -> Mission:
    """The mission file with the options applied (see the module docstring)."""
    mission = load_mission(args.mission, _overrides(args))
    if args.seed is not None:
        mission = mission.with_seed(args.seed)
    return apply_ardupilot_options(_px4_options(mission, args), args)


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {
        key: getattr(args, key) for key in MISSION_FIELDS if getattr(args, key) is not None
    }
    if args.instruction:  # the command line's instructions replace the file's, one or a list
        out.update(instruction=None, instructions=list(args.instruction))
    return out


def _px4_options(mission: Mission, args: argparse.Namespace) -> Mission:
    """Apply --px4 / --px4-speed (px4-sitl only), resolving the PX4 folder now: a bad one is named at once."""
    if mission.vehicle != PX4_SITL and args.px4 is None and args.px4_speed is None:
        return mission
    from sim_world.px4_bridge.px4_process import find_px4_dir  # the simulator only when it is flown

    if args.px4 is None and args.px4_speed is None:
        if mission.vehicle == PX4_SITL:
            find_px4_dir(mission.px4.dir)
        return mission
    if mission.vehicle != PX4_SITL:
        raise ValueError(
            f"--px4 and --px4-speed go with --vehicle px4-sitl (the vehicle is {mission.vehicle!r})"
        )
    update: dict[str, Any] = {}
    if args.px4 is not None or mission.px4.dir is not None:
        update["dir"] = str(find_px4_dir(args.px4 if args.px4 is not None else mission.px4.dir))
    if args.px4_speed is not None:
        update["speed"] = args.px4_speed if args.px4_speed == "max" else float(args.px4_speed)
    px4 = Px4Spec.model_validate({**mission.px4.model_dump(), **update})
    return mission.model_copy(update={"px4": px4})
