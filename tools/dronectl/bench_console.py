"""`dronectl bench console`: the console in a real browser: page frame rate, camera-to-page latency, and
Hold from the button to HOLD mode in the vehicle's telemetry (`controller.benchmarks.console`).

    dronectl bench console                          # the in-process simulation
    dronectl bench console --vehicle sim-mavlink --holds 20
    dronectl bench console --vehicle px4-sitl --px4 DIR --holds 20

Needs Debian's Chromium (/usr/bin/chromium) and the playwright package (the test extra).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from controller.missions.schema import MissionFileError, load_mission
from dronectl.options import CommandParser, at_least, new_file, positive_float, write_result

REPO = Path(__file__).resolve().parents[2]
DEFAULT_MISSION = REPO / "missions" / "regression" / "three_targets.yaml"
PROG = "dronectl bench console"


def main(argv: list[str]) -> int:
    parser = CommandParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--mission", type=Path, default=DEFAULT_MISSION, help="default: %(default)s")
    parser.add_argument("--vehicle", default="sim", help="sim, sim-mavlink, px4-sitl, ardupilot-sitl")
    parser.add_argument("--px4", type=Path, help="px4-sitl: the PX4 SITL build folder")
    parser.add_argument("--holds", type=at_least(1, 200), default=10, help="Holds to time (default 10)")
    parser.add_argument("--video-s", type=positive_float, default=10.0, help="seconds of video measured")
    parser.add_argument("--fps", type=positive_float, default=20.0, help="the console's --fps")
    parser.add_argument("--json", type=new_file, help="also write the figures to this new file")
    args = parser.parse_args(argv)
    from controller.benchmarks.browser import chromium_missing

    missing = chromium_missing()
    if missing is not None:
        print(f"{PROG}: {missing}", file=sys.stderr)
        return 2
    overrides = {"vehicle": args.vehicle} | ({"px4": {"dir": str(args.px4)}} if args.px4 else {})
    try:
        mission = load_mission(args.mission, overrides)
    except (MissionFileError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    from controller.benchmarks.console import ConsoleBenchSettings, run_console_bench

    with tempfile.TemporaryDirectory(prefix="bench-console-") as folder:
        settings = ConsoleBenchSettings(
            mission, Path(folder) / "session", video_s=args.video_s, holds=args.holds, fps=args.fps
        )
        result = run_console_bench(settings)
    lat, hold = result.latency_ms, result.hold_summary
    print(f"console on {result.vehicle}, frames {result.frame_px[0]}x{result.frame_px[1]} px")
    print(f"  page frame rate: {result.page_fps:.1f} fps ({result.page_frames} frames, {result.video_s:g} s)")
    if lat:
        print(f"  camera to page: p50 {lat['p50']:.0f} ms, p95 {lat['p95']:.0f} ms, max {lat['max']:.0f} ms "
              f"(n {lat['n']})")  # fmt: skip
    if hold:
        print(f"  Hold button to HOLD mode: p50 {hold['p50']:.3f} s, p95 {hold['p95']:.3f} s, "
              f"max {hold['max']:.3f} s (n {hold['n']})")  # fmt: skip
    if result.hold_to_thread_s:
        part = sorted(result.hold_to_thread_s)[len(result.hold_to_thread_s) // 2]
        call = sorted(result.hold_call_s)[len(result.hold_call_s) // 2]
        print(f"    click to the command thread (page, WebSocket, server): p50 {part:.3f} s; "
              f"the session's hold() call: p50 {call:.3f} s")  # fmt: skip
    for note in result.notes:
        print(f"  note: {note}")
    write_result(args.json, result.as_dict())
    if args.json is None:
        print(json.dumps({"hold_s": result.hold_s}))
    return 0
