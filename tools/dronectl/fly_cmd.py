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

import logging
import sys
import time
from pathlib import Path
from typing import Any

from controller.missions.results import MissionResult
from controller.missions.schema import MissionFileError
from drone_inspect_core.files import OutputDirError, claim_fresh_dir
from dronectl.mission_options import add_mission_options, mission_from_args
from dronectl.options import CommandParser, say_error, signing_key


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
    add_mission_options(parser, instructions=True)
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
    parser.add_argument("-v", "--verbose", action="store_true", help="log every module's progress")
    args = parser.parse_args(argv)
    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
        logging.getLogger("flight.mavsdk.vehicle").setLevel(logging.INFO)  # what a wait is waiting for
    try:
        mission = mission_from_args(args)
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
