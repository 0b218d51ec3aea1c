"""The ArduPilot simulator's process entry point: `python -m sim_world.ardupilot_bridge --config FILE.json`.

What launchers start (the `ardupilot-sitl` mission kit, `dronectl bench ardupilot`): the config is
`to_json` form of an `ArduPilotSimConfig`. It watches its parent and stops (ArduPilot
included) when the parent is gone. People use `dronectl ardupilot-sim`.
"""

from __future__ import annotations

import sys
from functools import partial

from drone_inspect_core.config_files import from_json
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig
from sim_world.ardupilot_bridge.serve import serve
from sim_world.process_entry import config_entry_point

if __name__ == "__main__":
    module, name = "sim_world.ardupilot_bridge", "ardupilot-sim"
    sys.exit(config_entry_point(sys.argv[1:], module, name, partial(from_json, ArduPilotSimConfig), serve))
