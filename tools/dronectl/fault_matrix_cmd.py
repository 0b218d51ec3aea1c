"""`dronectl fault-matrix`: the same randomised missions under each injected fault, as a markdown table.

    dronectl fault-matrix --vehicle sim-mavlink --n 20 --seed 1 --parallel 2 --out fault_matrix.md

Rows: no fault, a lossy and late link, a bad radio, dropped frames, a frozen picture, a
dying stream, gusts, a dying vehicle (see `controller.benchmarks.fault_matrix.DEFAULT_ROWS`). Each row
also gives the `dronectl benchmark-missions` command that reproduces it alone.
"""

from __future__ import annotations

import logging
import sys
from typing import Any

from controller.benchmarks.fault_matrix import format_markdown, run_fault_matrix
from controller.benchmarks.missions import BenchmarkConfig
from drone_inspect_core.files import write_atomic, write_json_atomic
from dronectl.ardupilot_options import FOLDER_HELP, resolve_ardupilot_dir
from dronectl.options import CommandParser, at_least, new_file, seed_value
from sim_world.px4_bridge.px4_process import find_px4_dir


def main(argv: list[str]) -> int:
    parser = CommandParser(prog="dronectl fault-matrix", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--vehicle", default="sim-mavlink", choices=("sim-mavlink", "px4-sitl", "ardupilot-sitl")
    )
    parser.add_argument("--px4", help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument("--ardupilot", help=FOLDER_HELP)
    parser.add_argument("--n", type=at_least(1), default=20, help="missions per fault (default: %(default)s)")
    parser.add_argument("--seed", type=seed_value, default=1, help="benchmark seed (default: %(default)s)")
    parser.add_argument("--planner", default="latent", help="one planner (default: %(default)s)")
    parser.add_argument(
        "--parallel", type=at_least(1), default=2, help="worker processes (default: %(default)s)"
    )
    parser.add_argument("--out", type=new_file, help="write the markdown table here")
    parser.add_argument("--json", type=new_file, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.WARNING)
    try:
        mission: dict[str, Any] = {"vehicle": args.vehicle}
        if args.vehicle == "px4-sitl":
            # a missing PX4 folder is named before anything flies
            mission["px4"] = {"dir": str(find_px4_dir(args.px4)), "speed": "max", "keep_ulog": False}
        if args.vehicle == "ardupilot-sitl":
            mission["ardupilot"] = {
                "dir": resolve_ardupilot_dir(args.ardupilot),
                "speed": "max",
                "keep_logs": False,
            }
        base = BenchmarkConfig.of(
            mission, n=args.n, seed=args.seed, planners=(args.planner,), parallel=args.parallel
        )
    except ValueError as exc:
        parser.error(str(exc))
    rows = run_fault_matrix(base)
    table = format_markdown(rows, base, command="dronectl fault-matrix " + " ".join(argv))
    print(table)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(args.out, table)
        print(f"wrote {args.out}", file=sys.stderr)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, rows, indent=1)
    return 0
