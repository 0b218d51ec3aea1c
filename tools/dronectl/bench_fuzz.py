"""`dronectl bench fuzz`: hostile MAVLink against flying missions (`controller.benchmarks.fuzz`)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import controller.benchmarks.fuzz as bench
from controller.benchmarks.fuzz import FuzzConfig, run_fuzz
from controller.missions.schema import load_mission
from drone_inspect_core.files import claimed_dir
from dronectl.options import CommandParser, at_least, new_file, positive_float, seed_value, write_result

DEFAULT_MISSION = Path(__file__).resolve().parents[2] / "missions" / "default.yaml"


def main(argv: list[str]) -> int:
    """0 when nothing crashed, nothing was obeyed from a stranger and every mission was centred."""
    parser = CommandParser(prog="dronectl bench fuzz", description=bench.__doc__.splitlines()[0])
    parser.add_argument("--vehicle", default="sim-mavlink", choices=("sim-mavlink", "px4-sitl"))
    parser.add_argument("--px4", help="px4-sitl: PX4 SITL build folder (default: $PX4_SITL_DIR)")
    parser.add_argument("--datagrams", type=at_least(0), default=100_000, help="random datagrams")
    parser.add_argument("--messages", type=at_least(0), default=10_000, help="hostile valid messages")
    parser.add_argument("--rate", type=positive_float, default=2500.0, help="hostile datagrams per second")
    parser.add_argument("--seed", type=seed_value, default=0, help="the attack's and the scenes' seed")
    parser.add_argument("--max-missions", type=at_least(1), default=20, help="at most this many missions")
    parser.add_argument("--mission", type=Path, default=DEFAULT_MISSION, help="the mission flown (a file)")
    parser.add_argument("--out", type=Path, help="keep the missions' report folders here (new or empty)")
    parser.add_argument("--json", type=new_file, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    try:
        config = FuzzConfig(
            vehicle=args.vehicle, datagrams=args.datagrams, messages=args.messages, rate_per_s=args.rate,
            seed=args.seed, max_missions=args.max_missions, px4_dir=args.px4,
        )  # fmt: skip
        overrides: dict[str, object] = {"vehicle": args.vehicle}
        if args.px4 is not None:
            overrides["px4"] = {"dir": args.px4}
        base = load_mission(args.mission, overrides)
    except ValueError as exc:
        parser.error(str(exc))
    if args.out is not None:
        with claimed_dir(args.out, "report folder") as out:
            report = run_fuzz(config, out, base)
    else:
        with tempfile.TemporaryDirectory(prefix="bench-fuzz-") as tmp:
            report = run_fuzz(config, Path(tmp), base)
    for m in report["missions"]:
        print("  " + _mission_line(m))
    print(
        f"fuzz, {args.vehicle}: {report['hostile_sent']} of {report['hostile_planned']} hostile datagrams "
        f"over {report['flown']} missions in {report['wall_s']:.0f} s: {report['crashes']} crashes, "
        f"{report['obeyed_from_strangers']} commands obeyed from a stranger, "
        f"{report['foreign_params_changed']} parameters changed by one; "
        f"{report['centred']}/{report['flown']} missions centred "
        f"(load average {report['load_average_before']:.1f} before, {report['cpus']} CPUs)"
    )
    write_result(args.json, json.loads(json.dumps(report, default=str)))
    ok = (
        report["crashes"] == 0
        and report["obeyed_from_strangers"] == 0
        and report["foreign_params_changed"] == 0
    )
    return 0 if ok and report["centred"] == report["flown"] else 1


def _mission_line(m: dict[str, Any]) -> str:
    relay, link = m["relay"], m["vehicle_link"] or {}
    crashed = ", ".join(m["crashed"]) or "none"
    parts = [
        f"{m['name']}: {m['outcome']}, {m['sent']} hostile datagrams, crashed: {crashed}",
        f"relay dropped {relay.get('dropped_foreign', 0)} foreign + {relay.get('dropped_unsigned', 0)} "
        f"unsigned, forwarded {relay.get('forwarded_to_vehicle', 0)} from MAVSDK",
    ]
    if link:
        parts.append(
            f"vehicle accepted {link['accepted']} (from {link['accepted_from']}), dropped "
            f"{link['dropped_foreign']} foreign + {link['dropped_unsigned']} unsigned + "
            f"{link['dropped_bad']} bad"
        )
    if m["bridge_connections_refused"]:
        parts.append(f"{m['bridge_connections_refused']} simulator-port connections refused")
    if m["error"]:
        parts.append(f"error: {m['error']}")
    return "; ".join(parts)
