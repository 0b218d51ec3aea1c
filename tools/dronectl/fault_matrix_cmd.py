"""`dronectl fault-matrix`: the same randomised missions under each injected fault, as a markdown table.

    dronectl fault-matrix --vehicle sim-mavlink --n 20 --seed 1 --parallel 2 --out fault_matrix.md

Rows: no fault, a lossy and late link, a bad radio, dropped frames, a frozen picture, a
dying stream, gusts, a dying vehicle (see `controller.benchmarks.fault_matrix.DEFAULT_ROWS`). Each row
also gives the `dronectl benchmark-missions` command that reproduces it alone.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Any

from controller.benchmarks.fault_matrix import format_markdown, run_fault_matrix
from controller.benchmarks.missions import BenchmarkConfig
from dronectl.ardupilot_options import FOLDER_HELP, resolve_ardupilot_dir


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="dronectl fault-matrix", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--vehicle", default="sim-mavlink", choices=("sim-mavlink", "px4-sitl", "ardupilot-sitl")
    )
    parser.add_argument("--px4", help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument("--ardupilot", help=FOLDER_HELP)
    parser.add_argument("--n", type=int, default=20, help="missions per fault (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="benchmark seed (default: %(default)s)")
    parser.add_argument("--planner", default="latent", help="one planner (default: %(default)s)")
    parser.add_argument("--parallel", type=int, default=2, help="worker processes (default: %(default)s)")
    parser.add_argument("--out", type=Path, help="write the markdown table here")
    parser.add_argument("--json", type=Path, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.WARNING)
    try:
        mission: dict[str, Any] = {"vehicle": args.vehicle}
        if args.vehicle == "px4-sitl":
            mission["px4"] = {"dir": args.px4, "speed": "max", "keep_ulog": False}
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
        args.out.write_text(table)
        print(f"wrote {args.out}", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0
