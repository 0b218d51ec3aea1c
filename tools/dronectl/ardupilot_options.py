"""The command-line options every flying command takes for `ardupilot-sitl` missions, written once.

`--ardupilot DIR` (the ArduCopter SITL folder; default $ARDUPILOT_SITL_DIR, else ../shared/ardupilot-sitl)
and `--ardupilot-speed` (simulated seconds per wall second, or max), for `dronectl fly`; the folder is
resolved when the options are applied, so a bad one is named before anything starts.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from controller.missions.schema import ArduPilotSpec, Mission
from controller.missions.vehicles import ARDUPILOT_SITL

FOLDER_HELP = (
    "ardupilot-sitl: the ArduCopter SITL folder (default: $ARDUPILOT_SITL_DIR, else ../shared/ardupilot-sitl)"
)


def add_ardupilot_options(parser: argparse.ArgumentParser, speed_default: str | None = None) -> None:
    parser.add_argument("--ardupilot", type=Path, help=FOLDER_HELP)
    default = speed_default or "the mission's, 1"
    parser.add_argument(
        "--ardupilot-speed",
        default=speed_default,
        help=f"ardupilot-sitl: simulated seconds per wall second, or 'max' (default: {default})",
    )


def resolve_ardupilot_dir(folder: str | Path | None) -> str:
    """The ArduPilot folder as a string, resolved now (`ArduPilotFolderError`, a ValueError, if none)."""
    from sim_world.ardupilot_bridge.ardupilot_process import find_ardupilot_dir  # the simulator: only here

    return str(find_ardupilot_dir(folder))


def apply_ardupilot_options(mission: Mission, args: argparse.Namespace) -> Mission:
    """Apply --ardupilot / --ardupilot-speed (ardupilot-sitl only), resolving the folder now."""
    if mission.vehicle != ARDUPILOT_SITL:
        if args.ardupilot is not None or args.ardupilot_speed is not None:
            raise ValueError(
                "--ardupilot and --ardupilot-speed go with --vehicle ardupilot-sitl "
                f"(the vehicle is {mission.vehicle!r})"
            )
        return mission
    update: dict[str, Any] = {
        "dir": resolve_ardupilot_dir(args.ardupilot if args.ardupilot is not None else mission.ardupilot.dir)
    }
    if args.ardupilot_speed is not None:
        speed = args.ardupilot_speed
        update["speed"] = speed if speed == "max" else float(speed)
    spec = ArduPilotSpec.model_validate({**mission.ardupilot.model_dump(), **update})
    return mission.model_copy(update={"ardupilot": spec})
