"""The simulated vehicle's process entry point: `python -m sim_world.mavlink --config FILE.json`.

What launchers start (`flight.sim_launcher`: the sim-mavlink missions, the flight tests and
benchmark); the config is `sim_vehicle_main.run_to_json`'s form of a `SimVehicleRun`. It
watches its parent and stops when the parent is gone. People use `dronectl sim-vehicle`.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from sim_world.sim_vehicle_main import run_from_json, serve


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != "--config":
        print("usage: python -m sim_world.mavlink --config FILE.json", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        run = run_from_json(json.loads(Path(argv[1]).read_text()))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"sim-vehicle: bad config {argv[1]}: {exc}", file=sys.stderr)
        return 2
    return serve(run, sys.stdout, watch_parent=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
