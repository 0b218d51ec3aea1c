"""`dronectl move`: connect, arm, take off, offboard, fly one discrete move, hold, land, disarm.

Two terminals, the simulated drone as a MAVLink vehicle:

    dronectl sim-vehicle
    dronectl move --right-m 0.5

PX4 SITL (it sends to udp 14540 too) or a real vehicle: the same command with
`--vehicle udpin://0.0.0.0:14540` or `--vehicle serial:///dev/ttyACM0:57600`;
`--vehicle sim` flies the in-process PyBullet backend instead (no MAVLink).
"""

from __future__ import annotations

import sys

from dronectl.options import CommandParser, add_signing_key, seed_value, signing_key
from flight.errors import FlightError
from flight.safety import SafetyLimits
from flight.scenario import SIM_VEHICLE, MoveFlight, fly_move, open_vehicle


def main(argv: list[str]) -> int:
    parser = CommandParser(prog="dronectl move", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--vehicle",
        default="udpin://0.0.0.0:14540",
        help=f"a MAVSDK URL (udpin://0.0.0.0:14540, serial:///dev/ttyACM0:57600) or {SIM_VEHICLE!r} "
        "for the in-process PyBullet backend (default: %(default)s)",
    )
    parser.add_argument("--right-m", type=float, default=0.0, help="move right (negative: left), m")
    parser.add_argument("--forward-m", type=float, default=0.0, help="move forward (negative: back), m")
    parser.add_argument("--down-m", type=float, default=0.0, help="move down (negative: up), m")
    parser.add_argument("--speed", type=float, default=0.25, help="move speed, m/s (default: %(default)s)")
    parser.add_argument(
        "--takeoff-alt", type=float, default=2.5, help="takeoff altitude, m (default: %(default)s)"
    )
    parser.add_argument("--max-speed", type=float, default=1.0, help="safety limit on horizontal speed, m/s")
    parser.add_argument("--seed", type=seed_value, default=0, help="world seed for --vehicle sim")
    add_signing_key(parser)
    args = parser.parse_args(argv)
    if args.right_m == 0.0 and args.forward_m == 0.0 and args.down_m == 0.0:
        parser.error(
            "give the move: at least one of --right-m, --forward-m, --down-m (an axis not given is 0)"
        )
    try:
        flight = MoveFlight(
            right_m=args.right_m,
            forward_m=args.forward_m,
            down_m=args.down_m,
            speed_m_s=args.speed,
            takeoff_alt_m=args.takeoff_alt,
        )
        limits = SafetyLimits(max_horizontal_speed_m_s=args.max_speed)
        key = signing_key(args)
    except ValueError as exc:
        parser.error(str(exc))
    print(f"connecting to {args.vehicle} ...")
    try:
        with open_vehicle(args.vehicle, seed=args.seed, signing_key=key) as vehicle:
            result = fly_move(vehicle, flight, limits)
    except FlightError as exc:
        print(f"dronectl move: {exc}", file=sys.stderr)
        return 1
    d = result.move.displacement
    t = result.timings
    f = flight
    print(f"commanded: right {f.right_m:+.2f} m, forward {f.forward_m:+.2f} m, down {f.down_m:+.2f} m")
    print(f"achieved:  right {d.right_m:+.3f} m, forward {d.forward_m:+.3f} m, down {d.down_m:+.3f} m")
    print(
        f"           (NED north {d.north_m:+.3f} m, east {d.east_m:+.3f} m; settled: {result.move.settled})"
    )
    print(
        f"offboard active after {t.offboard_active_s:.1f} s, move {result.move.wall_time_s:.1f} s, "
        f"landed and disarmed after {t.landed_s:.1f} s"
    )
    return 0
