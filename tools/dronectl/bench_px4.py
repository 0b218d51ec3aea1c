"""`dronectl bench px4`: real PX4 SITL in lockstep, measured through MAVSDK (`controller.benchmarks.px4`)."""

from __future__ import annotations

from pathlib import Path

import controller.benchmarks.px4 as bench
from controller.benchmarks.px4 import run_px4_bench
from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, new_file, positive_float, px4_instance_value
from sim_world.px4_bridge.px4_process import find_px4_dir


def main(argv: list[str]) -> int:
    """`dronectl bench px4 [--px4 DIR] [--instance N] [--hover-s S] [--json FILE]`; 0: all targets met."""
    parser = CommandParser(prog="dronectl bench px4", description=bench.__doc__.splitlines()[0])
    parser.add_argument("--px4", type=Path, help="PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument(
        "--instance", type=px4_instance_value, default="auto", help="PX4 instance 0..9 or auto (default)"
    )
    parser.add_argument(
        "--hover-s", type=positive_float, default=30.0, help="hover length, simulated seconds (default 30)"
    )
    parser.add_argument("--json", type=new_file, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    try:
        px4_dir = find_px4_dir(args.px4)
    except ValueError as exc:
        parser.error(str(exc))
    report = run_px4_bench(px4_dir, args.instance, args.hover_s)
    r, w, n, met = report["real_time"], report["with_camera"], report["without_camera"], report["target_met"]

    def ok(name: str) -> str:
        return "ok" if met[name] else "MISSED"

    print(f"PX4 SITL benchmark ({px4_dir}, instance {args.instance}, 224 px camera at 30 Hz unless said)")
    print(
        f"  1x real time: PX4 start -> lockstep {r['start_to_lockstep_wall_s']:.2f} s wall; estimator ready "
        f"(local position + home) after {r['ready_sim_s']:.2f} s simulated  "
        f"[target <= 15 s: {ok('ready_sim_s')}]"
    )
    print(
        f"  1x real time: hover {r['hover_sim_s']:.0f} s, drift per truth {r['hover_drift_m']:.3f} m "
        f"[target <= 0.3 m: {ok('hover_drift_m')}]"
    )
    print(f"  --speed max, hover: x{w['speed_x']:.2f} real time  [target >= 1.5: {ok('speed_camera_x')}]")
    print(
        f"  --speed max, hover without camera: x{n['speed_x']:.2f} real time  "
        f"[target >= 5: {ok('speed_no_camera_x')}]"
    )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, report, indent=2)
        print(f"wrote {args.json}")
    return 0 if all(met.values()) else 1
