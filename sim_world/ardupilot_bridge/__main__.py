"""The ArduPilot simulator's process entry point: `python -m sim_world.ardupilot_bridge --config FILE.json`.

What launchers start (the `ardupilot-sitl` mission kit, `dronectl bench ardupilot`): the config is
`serve.config_to_json`'s form of an `ArduPilotSimConfig`. It watches its parent and stops (ArduPilot
included) when the parent is gone. People use `dronectl ardupilot-sim`.
"""

from __future__ import annotations

import sys

from sim_world.ardupilot_bridge.serve import config_from_json, serve
from sim_world.process_entry import config_entry_point

if __name__ == "__main__":
    module, name = "sim_world.ardupilot_bridge", "ardupilot-sim"
    sys.exit(config_entry_point(sys.argv[1:], module, name, config_from_json, serve))
