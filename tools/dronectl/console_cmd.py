"""`dronectl console`: a live operator's console in the browser, on one flight of a mission's vehicle.

    dronectl console                                   # the in-process simulation, missions/default.yaml
    dronectl console --vehicle sim-mavlink --mission missions/regression/multi_three.yaml
    dronectl console --vehicle px4-sitl --px4 DIR      # real PX4 SITL; ardupilot-sitl likewise
    dronectl console --vehicle udpin://0.0.0.0:14540 --camera http://drone:8080/stream.mjpg

It prints the page's address, served on 127.0.0.1 with a token made for this run; open it in a browser
on this machine. `--host ADDR` serves on another address (explicitly; the token is still needed there).
On the page: the live camera with every detection, the ε box and the image centre; the planner's nine
distances; mode, armed, altitude, link, setpoint age, battery; an instruction box (type, Enter: the
centring loop flies), Take off, Hold, Land and Kill (which asks to confirm). One page commands, others
watch. The session is one report folder (`--out`), report.json with an entry per instruction.
Ctrl-C (or SIGTERM) lands a vehicle still flying, writes the report and stops. Exit status 0 after a
clean stop, 1 when the console could not start, 2 on a bad option or mission file.
"""

from __future__ import annotations

import ipaddress
import logging
import sys
import time
from pathlib import Path

from controller.missions.report import claim_report_dir
from controller.missions.schema import MissionFileError
from drone_inspect_core.files import OutputDirError, claim_fresh_dir
from dronectl.fly_cmd import summary_lines
from dronectl.mission_options import add_mission_options, mission_from_args
from dronectl.options import CommandParser, at_least, positive_float, say_error, signing_key

PROG = "dronectl console"


def _parser() -> CommandParser:
    parser = CommandParser(prog=PROG, description=__doc__.splitlines()[0])
    add_mission_options(parser, instructions=False)  # the instructions come from the page, one by one
    parser.add_argument(
        "--out",
        type=Path,
        help="the session's report folder, new or empty (default: a fresh runs/console/<mission>-<time>)",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="serve the page on this address (default: %(default)s, this machine only); another address "
        "lets other machines reach the page, which still needs the printed token",
    )
    parser.add_argument("--port", type=at_least(0, 65535), default=0, help="port (default: a free one)")
    parser.add_argument("--fps", type=positive_float, default=20.0, help="most video frames per second sent")
    parser.add_argument(
        "--sim-pace",
        type=positive_float,
        default=1.0,
        help="vehicle sim: simulated seconds per wall second (default: %(default)s, real time)",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log every module's progress")
    return parser


def _check_host(host: str) -> str | None:
    """None for an address this machine may serve on; the reason otherwise."""
    try:
        ipaddress.ip_address(host)
    except ValueError:
        if host != "localhost":
            return f"--host {host!r} is not an IP address (give one, e.g. 127.0.0.1 or 0.0.0.0)"
    return None


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
    from controller.console.run import ConsoleOptions, open_console  # uvicorn, torch: after the options

    try:
        mission = mission_from_args(args)
        key = signing_key(args)
        bad_host = _check_host(args.host)
        if bad_host is not None:
            raise ValueError(bad_host)
        default_out = Path("runs") / "console" / f"{mission.name}-{time.strftime('%Y%m%d-%H%M%S')}"
        # A given --out is this run's or an error; a default one is the first free name (runs at once).
        out = claim_report_dir(args.out) if args.out else claim_fresh_dir(default_out, "report folder")
        options = ConsoleOptions(
            mission, out, args.host, args.port, fps=args.fps, sim_pace=args.sim_pace, signing_key=key
        )
    except (MissionFileError, ValueError, OutputDirError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    print(f"opening the console for {mission.name} ({mission.vehicle}, planner {mission.planner}) ...")
    console = None
    try:
        with open_console(options) as console:
            if not ipaddress.ip_address("127.0.0.1" if args.host == "localhost" else args.host).is_loopback:
                print(f"serving on {args.host}: other machines can reach this page (with its token)")
            print(f"console: {console.url}", flush=True)
            print("Ctrl-C lands a vehicle still flying, writes the report and stops.", flush=True)
            while True:
                time.sleep(0.5)
    except KeyboardInterrupt:
        raise  # cli.py: after the session's exit has landed the vehicle and written the report
    except Exception as exc:
        say_error(PROG, f"{mission.name}: {type(exc).__name__}: {exc} (report: {out / 'report.json'})")
        return 1
    finally:
        result = None if console is None else console.session.result
        if result is not None:
            print("\n".join(summary_lines(result)))
    return 0
