"""`dronectl bench missions`: the same missions flown each way in one run, their phases and wall-time ratios.

    dronectl bench missions --n 20 --seed 11 --planner latent --parallel 2
    dronectl bench missions --ways sim,sim-mavlink --n 4 --json runs/ways.json

Takes every option of `dronectl benchmark-missions` (the missions each way flies) except `--vehicle`,
which `--ways` replaces; the simulated MAVLink vehicles fly at `max` speed unless told otherwise.
Prints per way the wall time, its ratio to the in-process way's, success and steps, and the mean wall
seconds per mission of each phase (`controller.missions.phases`); `--json FILE` writes the same and
every way's figures in full. The measuring is `controller.benchmarks.mission_ways`.
"""

from __future__ import annotations

import argparse
import logging

from controller.benchmarks.mission_ways import format_ways, run_ways
from controller.missions.schema import SIMULATED_VEHICLES
from dronectl.benchmark_missions_cmd import benchmark_config, build_parser
from dronectl.options import write_result

DEFAULT_WAYS = ("sim", "sim-mavlink", "px4-sitl", "ardupilot-sitl")


def _ways(text: str) -> tuple[str, ...]:
    ways = tuple(w.strip() for w in text.split(",") if w.strip())
    unknown = [w for w in ways if w not in SIMULATED_VEHICLES]
    if unknown or not ways:
        raise argparse.ArgumentTypeError(
            f"ways must be a comma-separated list of {', '.join(SIMULATED_VEHICLES)}; got {text!r}"
        )
    return ways


def main(argv: list[str]) -> int:
    parser = build_parser("dronectl bench missions", __doc__.splitlines()[0])
    parser.add_argument(
        "--ways",
        type=_ways,
        default=DEFAULT_WAYS,
        help=f"the ways to fly the missions, in this order (default: {','.join(DEFAULT_WAYS)})",
    )
    parser.set_defaults(n=20, sim_speed="max")
    args = parser.parse_args(argv)
    if args.vehicle is not None:
        parser.error("--vehicle: give the ways to fly with --ways")
    if args.report is not None or args.rerun:
        parser.error("--report/--rerun: keep one way's reports with `dronectl benchmark-missions`")
    logging.getLogger().setLevel(logging.WARNING)
    configs = {}
    for way in args.ways:
        args.vehicle = way
        config = benchmark_config(args, parser)
        if config is None:
            return 2
        configs[way] = config
    report = run_ways(configs)
    print(format_ways(report))
    write_result(args.json, report)
    return 0
