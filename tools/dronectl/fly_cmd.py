"""`dronectl fly`: fly one centring mission and write its report folder.

With no arguments it flies `missions/default.yaml` in the in-process simulation
with the shipped latent planner checkpoint:

    dronectl fly
    dronectl fly --mission missions/sector_ne.yaml --planner classic --out runs/fly/ne
    dronectl fly --seed 7 --epsilon-px 6
    dronectl fly --instruction "centre the pressure gauge"
    dronectl fly --mission missions/regression/three_instructions.yaml   # three targets, one flight
    dronectl fly --mission FILE --instruction "the gauge" --instruction "the red valve"

Each `--instruction` is centred in turn in one flight (take off once, hold between them, land once); the
words are understood before takeoff, and one the vocabulary cannot act on is refused in one line naming
the word and the closest known ones. The options change the mission file's fields and are validated by
the same mission model (an error names the option's field).

Real PX4 firmware (SITL) flying the simulated world: `--vehicle px4-sitl --px4 DIR`
(DIR: a PX4 SITL build folder, default $PX4_SITL_DIR); real ArduPilot: `--vehicle ardupilot-sitl`
(`--ardupilot DIR`, default $ARDUPILOT_SITL_DIR, else ../shared/ardupilot-sitl).

A real vehicle: a mission file with `vehicle: udpin://0.0.0.0:14540` and
`camera: http://<drone>:8080/stream.mjpg` (or the same as --vehicle/--camera); one set up with
MAVLink 2 signing: `--signing-key FILE` (32 bytes as 64 hex digits or base64).
Exit status 0 when the mission's expectations hold, 1 when they do not, 2 on a
bad mission file or option.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import Any

from controller.missions.results import MissionResult
from controller.missions.schema import (
    PX4_SITL,
    Mission,
    MissionFileError,
    Px4Spec,
    load_mission,
)
from controller.planning.planners import PLANNER_NAMES
from drone_inspect_core.files import OutputDirError, claim_fresh_dir
from dronectl.ardupilot_options import add_ardupilot_options, apply_ardupilot_options
from dronectl.options import CommandParser, add_signing_key, at_least, say_error, seed_value, signing_key

DEFAULT_MISSION = Path(__file__).resolve().parents[2] / "missions" / "default.yaml"


MISSION_FIELDS = (
    "planner", "checkpoint", "epsilon_px", "max_steps", "timeout_s", "vehicle", "camera", "sim_speed",
    "target_kind", "targets",
)  # fmt: skip
"""The mission fields an option of the same name changes (`Mission` validates them)."""


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


def summary_lines(result: MissionResult) -> list[str]:
    """The few lines a person wants after a flight."""
    verdict = "PASS" if result.passed else "FAIL"
    outcome = result.outcome.replace("_", " ")
    refined = f", {result.refinement_moves} of them boundary refinement" if result.refinement_moves else ""
    if result.second_choice_moves:
        refined += f", {result.second_choice_moves} on the planner's second choice"
    lines = [
        f"{verdict}  {result.name}: {outcome} after {result.steps} steps "
        f"({result.moves} moves{refined}; {result.vehicle_s:.1f} s of flight)"
    ]
    truth, det = result.final_truth_offset_px, result.final_detector_offset_px
    parts = []
    if truth is not None:
        parts.append(f"truth ({truth[0]:+.1f}, {truth[1]:+.1f}) px")
    if det is not None:
        parts.append(f"detector ({det[0]:+.1f}, {det[1]:+.1f}) px")
    lines.append(
        f"      final offset: {', '.join(parts) or 'target not in view'}; ε = {result.epsilon_px:g} px"
    )
    if result.overhead_ms_mean is not None:
        lines.append(f"      loop overhead: {result.overhead_ms_mean:.1f} ms per step (besides the move)")
    if len(result.instructions) > 1:
        lines += [_instruction_line(entry) for entry in result.instructions]
    lines += [f"      - {failure}" for failure in result.failures]
    lines += [f"      not recorded: {error}" for error in result.recording_errors]
    if result.report_dir and result.report_written:
        extra = [name for key, name in result.files.items() if name and key != "report"]
        also = f" (+ {', '.join(extra)})" if extra else ""
        lines.append(f"      report: {Path(result.report_dir) / 'report.json'}{also}")
    elif result.report_dir:
        lines.append(f"      report: could not be written in {result.report_dir} (the outcome is above)")
    return lines


def _instruction_line(entry: dict[str, Any]) -> str:
    """One instruction of a flight of several, in a line."""
    truth = entry["final_truth_offset_px"]
    where = "" if truth is None else f"; truth ({truth[0]:+.1f}, {truth[1]:+.1f}) px"
    wrong = "; WRONG TARGET" if entry["wrong_target"] else ""
    verdict = "pass" if entry["passed"] else "FAIL"
    outcome = entry["outcome"].replace("_", " ")
    what = f"{verdict} {entry['instruction']!r}: {outcome} after {entry['steps']} steps"
    return f"      {entry['index']}. {what}{where}{wrong}"


def main(argv: list[str]) -> int:
    parser = CommandParser(prog="dronectl fly", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--mission", type=Path, default=DEFAULT_MISSION, help="mission YAML (default: %(default)s)"
    )
    parser.add_argument("--planner", choices=PLANNER_NAMES, help="override the mission's planner")
    parser.add_argument("--checkpoint", help="latent planner checkpoint folder (default: the shipped one)")
    parser.add_argument("--seed", type=seed_value, help="override the scene seed (and a random start's seed)")
    parser.add_argument("--epsilon-px", type=float, help="override ε, pixels")
    parser.add_argument("--max-steps", type=at_least(1), help="override the step budget (per instruction)")
    parser.add_argument("--timeout-s", type=float, help="override the time budget (per instruction), seconds")
    parser.add_argument(
        "--instruction",
        action="append",
        metavar="TEXT",
        help="what to centre, e.g. 'centre the red valve'; repeat it to centre several in one flight "
        "(replaces the mission's instructions)",
    )
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
    parser.add_argument(
        "--out",
        type=Path,
        help="report folder; must be new or empty: a report is never written over another "
        "(default: a fresh runs/fly/<mission>-<time>)",
    )
    parser.add_argument(
        "--rerun",
        type=Path,
        metavar="FILE.rrd",
        help="also record the flight for the Rerun viewer (a new file; needs the [rerun] extra)",
    )
    add_signing_key(parser)
    parser.add_argument("-v", "--verbose", action="store_true", help="log every module's progress")
    args = parser.parse_args(argv)
    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
        logging.getLogger("flight.mavsdk.vehicle").setLevel(logging.INFO)  # what a wait is waiting for
    try:
        mission = load_mission(args.mission, _overrides(args))
        if args.seed is not None:
            mission = mission.with_seed(args.seed)
        mission = apply_ardupilot_options(_px4_options(mission, args), args)
        key = signing_key(args)
        if key is not None and not mission.is_real:
            raise ValueError(
                f"--signing-key is for a real vehicle set up with that key; {mission.vehicle} gets a key "
                "of its own per run (sim-mavlink) or cannot sign (px4-sitl, ardupilot-sitl, sim)"
            )
    except (MissionFileError, ValueError) as exc:
        print(f"dronectl fly: {exc}", file=sys.stderr)
        return 2
    from controller.missions.report import claim_report_dir
    from controller.missions.runner import run_mission

    if args.rerun is not None:
        from controller.missions.rerun_log import RerunFileError, RerunUnavailableError, check_rerun_path

        try:
            check_rerun_path(args.rerun)
        except (RerunFileError, RerunUnavailableError) as exc:
            print(f"dronectl fly: {exc}", file=sys.stderr)
            return 2
    default_out = Path("runs") / "fly" / f"{mission.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        # A given --out is this run's or an error; a default one is the first free name (runs at once).
        out = claim_report_dir(args.out) if args.out else claim_fresh_dir(default_out, "report folder")
    except OutputDirError as exc:
        print(f"dronectl fly: --out {exc}", file=sys.stderr)
        return 2
    print(f"flying {mission.name} ({mission.vehicle}, planner {mission.planner}) ...", flush=True)
    try:
        result = run_mission(mission, out, rerun_path=args.rerun, claimed=True, signing_key=key)
    except Exception as exc:  # could not start: a clear line, not a traceback
        why = f"{type(exc).__name__}: {exc}"
        say_error("dronectl fly", f"{mission.name} could not start: {why} (report: {out / 'report.json'})")
        return 1
    print("\n".join(summary_lines(result)))
    if args.rerun is not None and args.rerun.exists():
        print(f"      rerun: {args.rerun} (open it with `rerun {args.rerun}`)")
    return 0 if result.passed else 1
