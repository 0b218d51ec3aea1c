"""The PX4 simulator's process entry point: `python -m sim_world.px4_bridge --config FILE.json`.

What launchers start (the `px4-sitl` mission kit, `dronectl bench px4`): the config is
`run.config_to_json`'s form of a `Px4SimConfig`, so nothing is parsed twice. It watches its
parent and stops (PX4 included) when the parent is gone. People use `dronectl px4-sim`.
"""

from __future__ import annotations

import sys

from sim_world.process_entry import config_entry_point
from sim_world.px4_bridge.run import config_from_json, serve

if __name__ == "__main__":
    sys.exit(config_entry_point(sys.argv[1:], "sim_world.px4_bridge", "px4-sim", config_from_json, serve))
