"""`dronectl bench flight`: the flight layer's speed (the measuring is `controller.benchmarks.flight`)."""

from __future__ import annotations

from typing import Any

import controller.benchmarks.flight as bench
from controller.benchmarks.flight import FlightBenchConfig, run_flight_bench
from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, add_signing_key, at_least, new_file, signing_key
from flight.errors import ConnectionUrlError
from flight.urls import validate_connection_url


def _print_report(report: dict[str, Any]) -> None:
    m, p, met = report["mavsdk"], report["pybullet"], report["target_met"]

    def ok(name: str) -> str:
        return "ok" if met[name] else "MISSED"

    marks = ", ".join(f"{k[:-2]} {v:.2f} s" for k, v in m["process_start_to"].items())
    ref = m["takeoff_then_offboard"]
    print(f"flight benchmark (loopback; vehicle: {m['vehicle']})")
    print(f"  from process start: {marks}")
    print(
        f"  discovery -> offboard active (arm, zero setpoint, offboard start on the ground): "
        f"{m['discovery_to_offboard_s']:.2f} s (arm wait incl. PX4's boot refusal "
        f"{m['arming_wait_s']:.2f} s, offboard confirm {m['offboard_confirm_s']:.2f} s)  "
        f"[target <= 5 s: {ok('discovery_to_offboard_s')}]"
    )
    print(f"  then climb to {report['move_altitude_m']:.1f} m in offboard: {m['offboard_climb_s']:.2f} s")
    if ref is not None:
        print(
            f"  reference, takeoff first (arm, NAV_TAKEOFF, offboard start): discovery -> offboard active "
            f"{ref['discovery_to_offboard_s']:.2f} s (process start -> discovery "
            f"{ref['process_start_to']['discovered_s']:.2f} s, arm wait {ref['arming_wait_s']:.2f} s, "
            f"takeoff climb {ref['takeoff_climb_s']:.2f} s, "
            f"offboard confirm {ref['offboard_confirm_s']:.2f} s)"
        )
    held, moving = m["setpoint_stream_holding"], m["setpoint_stream_moving"]
    print(
        f"  setpoints at the vehicle while moving: {moving['rate_hz']:.2f} Hz, largest gap "
        f"{moving['max_gap_ms']:.0f} ms  [target >= 20 Hz: {ok('setpoint_rate_hz')}]"
    )
    print(
        f"  setpoints while holding (MAVSDK's own re-send only): {held['rate_hz']:.2f} Hz, "
        f"largest gap {held['max_gap_ms']:.0f} ms"
    )
    rtt = m["command_rtt_ms"]
    print(
        f"  command round trip: p50 {rtt['p50']:.2f} ms, p99 {rtt['p99']:.2f} ms (n={rtt['n']})  "
        f"[target p99 <= 50 ms: {ok('command_rtt_p99_ms')}]"
    )
    print(
        f"  one move, MAVSDK backend: {m['move_wall_s']:.2f} s wall, "
        f"achieved right {m['move_right_m']:+.3f} m"
    )
    print(
        f"  one move, PyBullet backend: {p['move_wall_s']:.3f} s wall, "
        f"achieved right {p['move_right_m']:+.3f} m (whole flight {p['flight_sim_s']:.1f} s simulated "
        f"in {p['flight_wall_s']:.2f} s, "
        f"x{p['faster_than_real_time']:.0f} real time)"
    )


def main(argv: list[str]) -> int:
    """`dronectl bench flight [--json FILE] [--vehicle URL [--signing-key FILE]]`; 0: every target met."""
    parser = CommandParser(prog="dronectl bench flight", description=bench.__doc__.splitlines()[0])
    parser.add_argument("--json", type=new_file, help="also write the numbers to this JSON file")
    parser.add_argument("--rtt-samples", type=at_least(1), default=200, help="command round trips to time")
    parser.add_argument(
        "--vehicle",
        help="fly a vehicle that is already running (e.g. udpin://0.0.0.0:14540 for `dronectl px4-sim`) "
        "instead of launching a sim-vehicle",
    )
    add_signing_key(parser)
    args = parser.parse_args(argv)
    try:
        key = signing_key(args)
        if key is not None and args.vehicle is None:
            raise ValueError("--signing-key goes with --vehicle URL (a launched sim-vehicle has its own key)")
        config = FlightBenchConfig(rtt_samples=args.rtt_samples, vehicle_url=args.vehicle, signing_key=key)
        if args.vehicle:
            validate_connection_url(args.vehicle)
    except (ValueError, ConnectionUrlError) as exc:
        parser.error(str(exc))
    report = run_flight_bench(config)
    _print_report(report)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, report, indent=2)
        print(f"wrote {args.json}")
    return 0 if all(report["target_met"].values()) else 1
