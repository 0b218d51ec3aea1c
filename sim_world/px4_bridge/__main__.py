"""The PX4 simulator's process entry point: `python -m sim_world.px4_bridge --config FILE.json`.

What launchers start (the `px4-sitl` mission kit, `dronectl bench px4`): the config is
`to_json` form of a `Px4SimConfig`, so nothing is parsed twice. It watches its
parent and stops (PX4 included) when the parent is gone. People use `dronectl px4-sim`.
"""

from __future__ import annotations

import sys
from functools import partial

from drone_inspect_core.config_files import from_json
from sim_world.process_entry import config_entry_point
from sim_world.px4_bridge.run import Px4SimConfig, serve

if __name__ == "__main__":
    load = partial(from_json, Px4SimConfig)
    sys.exit(config_entry_point(sys.argv[1:], "sim_world.px4_bridge", "px4-sim", load, serve))
