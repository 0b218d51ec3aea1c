"""`dronectl missions run DIR`: fly every mission of a folder, print a table, write JUnit XML.

    dronectl missions run missions/regression --junit runs/missions.xml --report runs/missions --parallel 2

Exit status 0 when every mission passed, 1 when any failed, 2 on a bad mission file.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

from controller.missions.report import fresh_report_dir
from controller.missions.schema import MissionFileError
from controller.missions.suite import SuiteOptions, format_table, run_suite, write_junit
from controller.planning.planners import PLANNER_NAMES
from drone_inspect_core.files import OutputDirError
from dronectl.ardupilot_options import FOLDER_HELP
from dronectl.options import CommandParser, at_least, new_file


def main(argv: list[str]) -> int:
    parser = CommandParser(prog="dronectl missions", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    run = sub.add_parser("run", help="fly every mission of a folder")
    run.add_argument("directory", type=Path, help="folder of mission YAML files")
    run.add_argument("--junit", type=new_file, help="write JUnit XML here")
    run.add_argument(
        "--report",
        type=Path,
        help="report folders go here; new or empty (default: a fresh runs/missions/<time>)",
    )
    run.add_argument(
        "--parallel", type=at_least(1), default=1, help="missions flown at once, one process each"
    )
    run.add_argument(
        "--tag", action="append", default=[], help="fly only missions with this tag (repeatable)"
    )
    run.add_argument(
        "--skip-tag", action="append", default=[], help="skip missions with this tag (repeatable)"
    )
    run.add_argument("--planner", choices=PLANNER_NAMES, help="fly every mission with this planner")
    run.add_argument(
        "--detector", choices=("image", "truth"), help="truth: sim truth (in-process only; debugging)"
    )
    run.add_argument("--checkpoint", help="fly every latent mission with this planner checkpoint")
    run.add_argument(
        "--px4", type=Path, help="PX4 SITL build folder for px4-sitl missions (default: $PX4_SITL_DIR)"
    )
    run.add_argument("--ardupilot", type=Path, help=FOLDER_HELP)
    run.add_argument("-v", "--verbose", action="store_true", help="log every module's progress")
    args = parser.parse_args(argv)
    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
    report = args.report or fresh_report_dir(Path("runs") / "missions" / time.strftime("%Y%m%d-%H%M%S"))
    chosen = {"planner": args.planner, "detector": args.detector, "checkpoint": args.checkpoint}
    overrides = {key: value for key, value in chosen.items() if value is not None} or None
    try:
        options = SuiteOptions(
            report_dir=report,
            parallel=args.parallel,
            overrides=overrides,
            tags=tuple(args.tag),
            exclude_tags=tuple(args.skip_tag),
            px4_dir=None if args.px4 is None else str(args.px4.resolve()),
            ardupilot_dir=None if args.ardupilot is None else str(args.ardupilot.resolve()),
        )
        suite = run_suite(args.directory, options)
    except (MissionFileError, ValueError, OutputDirError) as exc:
        print(f"dronectl missions: {exc}", file=sys.stderr)
        return 2
    print(format_table(suite))
    print(f"reports: {report}")
    if args.junit:
        write_junit(suite, args.junit)
        print(f"JUnit XML: {args.junit}")
    return 0 if suite.passed else 1
