"""`dronectl bench ardupilot`: real ArduCopter SITL in lockstep, measured through the GUIDED backend
(see `controller.benchmarks.ardupilot`)."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import controller.benchmarks.ardupilot as bench
from controller.benchmarks.ardupilot import run_ardupilot_bench
from sim_world.ardupilot_bridge.ardupilot_process import find_ardupilot_dir


def main(argv: list[str]) -> int:
    """`dronectl bench ardupilot [--ardupilot DIR] [--instance N] [--hover-s S] [--real-time] [--json FILE]`;
    0: all targets met."""
    parser = argparse.ArgumentParser(
        prog="dronectl bench ardupilot", description=bench.__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--ardupilot", type=Path, help="ArduCopter SITL folder (default: $ARDUPILOT_SITL_DIR, ...)"
    )
    parser.add_argument("--instance", type=int, default=8, help="ArduPilot instance (default %(default)s)")
    parser.add_argument("--hover-s", type=float, default=30.0, help="hover length, simulated seconds")
    parser.add_argument("--real-time", action="store_true", help="fly the camera run at 1x real time")
    parser.add_argument("--json", type=Path, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    try:
        ardupilot_dir = find_ardupilot_dir(args.ardupilot)
    except ValueError as exc:
        parser.error(str(exc))
    report = run_ardupilot_bench(ardupilot_dir, args.instance, args.hover_s, args.real_time)
    w, n, met = report["with_camera"], report["without_camera"], report["target_met"]

    def ok(name: str) -> str:
        return "ok" if met[name] else "MISSED"

    load = " / ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"ArduPilot SITL benchmark ({ardupilot_dir}, instance {args.instance}; load average {load})")
    print(
        f"  camera run ({w['speed']}): ArduPilot start -> first physics frame "
        f"{w['start_to_first_frame_wall_s']:.2f} s wall; EKF ready (position + home) after "
        f"{w['ready_sim_s']:.2f} s simulated  [target <= 45 s: {ok('ready_sim_s')}]"
    )
    print(
        f"  hover {w['hover_sim_s']:.0f} s in BRAKE, drift per truth {w['hover_drift_m']:.3f} m "
        f"[target <= 0.3 m: {ok('hover_drift_m')}]"
    )
    print(f"  lockstep with the 224 px camera at 30 Hz: x{w['speed_x']:.2f} real time  [target >= 2: "
          f"{ok('speed_camera_x')}]")  # fmt: skip
    print(
        f"  lockstep without the camera: x{n['speed_x']:.2f} real time  "
        f"[target >= 8: {ok('speed_no_camera_x')}]"
    )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0 if all(met.values()) else 1
