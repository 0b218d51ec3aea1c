"""`dronectl bench disk-full`: the disk fills mid-flight (`controller.benchmarks.disk_full`)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import controller.benchmarks.disk_full as bench
from controller.benchmarks.disk_full import MountError, run_disk_full
from controller.missions.schema import load_mission
from dronectl.options import CommandParser, at_least, new_file, seed_value, write_result

DEFAULT_MISSION = Path(__file__).resolve().parents[2] / "missions" / "default.yaml"


def main(argv: list[str]) -> int:
    """0 when every flight landed by the controller and reported its outcome whole."""
    parser = CommandParser(prog="dronectl bench disk-full", description=bench.__doc__.splitlines()[0])
    parser.add_argument("--n", type=at_least(1), default=20, help="missions (default: %(default)s)")
    parser.add_argument("--seed", type=seed_value, default=0, help="the scenes' and the moments' seed")
    parser.add_argument("--size-kb", type=at_least(256), default=2048, help="each mission's tmpfs, kB")
    parser.add_argument(
        "--max-tlog-kb",
        type=at_least(5),
        default=90,
        help="the disk fills when the .tlog reaches a random size up to this (default 90 kB: a sim-mavlink "
        "flight at --sim-speed max logs about 110-130 kB)",
    )
    parser.add_argument(
        "--sim-speed", default="max", help="the sim-vehicle's speed, a factor or 'max' (default: max)"
    )
    parser.add_argument("--mission", type=Path, default=DEFAULT_MISSION, help="the mission flown (a file)")
    parser.add_argument("--json", type=new_file, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    try:
        base = load_mission(args.mission, {"vehicle": "sim-mavlink", "sim_speed": args.sim_speed})
    except ValueError as exc:
        parser.error(str(exc))
    with tempfile.TemporaryDirectory(prefix="bench-disk-full-") as tmp:
        try:
            report = run_disk_full(base, Path(tmp), args.n, args.seed, args.size_kb, args.max_tlog_kb)
        except MountError as exc:
            parser.error(f"{exc.strerror} (mounting a tmpfs needs root)")
    for r in report["runs"]:
        said = f"; not recorded: {' | '.join(r['recording_errors'])}" if r["recording_errors"] else ""
        left = f"; LEFT AS IF WHOLE: {r['left_as_if_whole']}" if r["left_as_if_whole"] else ""
        print(
            f"  {r['name']}: {r['outcome']}, disk filled at a {r['fill_at_tlog_bytes'] // 1024} kB .tlog "
            f"({'during' if r['filled_during_flight'] else 'after'} the flight); landed by the controller: "
            f"{r['landed_by_controller']}; report complete: {r['report_complete']}{said}{left}"
            + (f"; error: {r['error']}" if r["error"] else "")
        )
    n = report["n"]
    print(
        f"disk full at a random moment, {n} sim-mavlink missions on {report['size_kb']} kB disks: "
        f"filled during the flight {report['filled_during_flight']}/{n}, landed by the controller "
        f"{report['landed_by_controller']}/{n}, outcome on the console {report['reported_on_console']}/{n}, "
        f"complete report.json {report['report_complete']}/{n}, files left as if whole "
        f"{report['left_as_if_whole']}, centred {report['centred']}/{n}; {report['wall_s']:.0f} s "
        f"(load average {report['load_average_before']:.1f} before, {report['cpus']} CPUs)"
    )
    write_result(args.json, report)
    whole = report["landed_by_controller"] == report["report_complete"] == report["reported_on_console"] == n
    return 0 if whole and report["left_as_if_whole"] == 0 else 1
