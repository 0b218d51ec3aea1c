"""The simulated vehicle's process entry point: `python -m sim_world.vehicle --config FILE.json`.

What launchers start (`flight.sim_launcher`: the sim-mavlink missions, the flight tests and
benchmark); the config is the `to_json` form of a `SimVehicleRun` (`serve.run_from_json` adds the key). It
watches its parent and stops when the parent is gone. People use `dronectl sim-vehicle`.
"""

from __future__ import annotations

import sys

from sim_world.process_entry import config_entry_point
from sim_world.vehicle.serve import run_from_json, serve

if __name__ == "__main__":
    sys.exit(config_entry_point(sys.argv[1:], "sim_world.vehicle", "sim-vehicle", run_from_json, serve))
