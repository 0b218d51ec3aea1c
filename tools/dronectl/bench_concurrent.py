"""`dronectl bench concurrent`: several `dronectl fly` at once (`controller.benchmarks.concurrent`)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import controller.benchmarks.concurrent as bench
from controller.benchmarks.concurrent import run_concurrent
from dronectl.options import CommandParser, at_least, new_file, write_result


def main(argv: list[str]) -> int:
    """0 when every flight passed, in its own folder, with its own vehicle."""
    parser = CommandParser(prog="dronectl bench concurrent", description=bench.__doc__.splitlines()[0])
    parser.add_argument("--n", type=at_least(2), default=4, help="flights at once (default: %(default)s)")
    parser.add_argument("--vehicle", default="sim-mavlink", choices=("sim-mavlink", "px4-sitl"))
    parser.add_argument("--px4", help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument("--json", type=new_file, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-concurrent-") as tmp:
        report = run_concurrent(args.n, args.vehicle, Path(tmp), args.px4)
    for r in report["runs"]:
        print(
            f"  exit {r['exit']}, system id {r['system_id']}, .tlog senders {r['tlog_senders']}, "
            f"folder {r['folder']}: {r['last_line'][:120]}"
        )
    n = report["n"]
    print(
        f"{n} x `dronectl fly --vehicle {args.vehicle}` at once, defaults: flew {report['flew']}/{n}, "
        f"own folder {report['own_folder']}/{n}, own vehicle {report['own_vehicle']}/{n}, shared system ids "
        f"{report['shared_system_ids']}, shared ports {report['shared_ports']}; {report['wall_s']:.0f} s "
        f"(load average {report['load_average_before']:.1f} before, {report['cpus']} CPUs)"
    )
    write_result(args.json, report)
    ok = report["flew"] == report["own_folder"] == report["own_vehicle"] == n
    return 0 if ok and not report["shared_system_ids"] and not report["shared_ports"] else 1
