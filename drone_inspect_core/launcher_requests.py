"""What a launcher asks of the simulator it started, after its config, as both ends read it.

A launcher (`flight.sim_launcher.SimulatorProcess`) gives a child its config on the first line of its
stdin and may keep that stdin open; each later line is one request, a JSON object:

- `{"reset": <the child's whole config as JSON>}`: a simulator kept warm between missions builds the new
  world (scene, seed, start, wind, camera faults) in the running process, keeping its ports, link and
  autopilot, and answers on stdout with one line `<the simulator's reset prefix>{json}`: its ready
  facts for the new world, or `{"error": "..."}`.
- `{"pace": 1}`: the client is waiting on the vehicle's clock: a lockstepped simulator paced by its
  client (`sim_world.sitl.rig.LockstepPace`) may run on a little further. No answer.
"""

from __future__ import annotations

import json
from typing import Any

RESET_REQUEST = "reset"
PACE_REQUEST = "pace"
PACE_LINE = json.dumps({PACE_REQUEST: 1}).encode() + b"\n"
"""The stdin line of a pace request."""


def reset_line(config: dict[str, Any]) -> bytes:
    """The stdin line asking for a reset to `config` (JSON-able)."""
    return json.dumps({RESET_REQUEST: config}).encode() + b"\n"


def reset_config(request: dict[str, Any]) -> dict[str, Any] | None:
    """The config a request asks to reset to; None if it is not a reset request."""
    config = request.get(RESET_REQUEST)
    return config if isinstance(config, dict) else None


def is_pace(request: dict[str, Any]) -> bool:
    return PACE_REQUEST in request
