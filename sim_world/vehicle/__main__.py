"""The simulated vehicle's process entry point: `python -m sim_world.vehicle --config FILE.json`.

What launchers start (`flight.sim_launcher`: the sim-mavlink missions, the flight tests and
benchmark); the config is `to_json` form of a `SimVehicleRun`. It
watches its parent and stops when the parent is gone. People use `dronectl sim-vehicle`.
"""

from __future__ import annotations

import sys
from functools import partial

from drone_inspect_core.config_files import from_json
from sim_world.process_entry import config_entry_point
from sim_world.vehicle.serve import SimVehicleRun, serve

if __name__ == "__main__":
    load = partial(from_json, SimVehicleRun)
    sys.exit(config_entry_point(sys.argv[1:], "sim_world.vehicle", "sim-vehicle", load, serve))
