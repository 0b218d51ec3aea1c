"""The launcher's requests to a simulator kept warm between missions, as both ends read them.

A launcher (`flight.sim_launcher.SimulatorProcess`) gives a child its config on the first line of its
stdin; a warm child's stdin stays open, and each later line is one request, a JSON object. The only one:
`{"reset": <the child's whole config as JSON>}`: build the new world (scene, seed, start, wind, camera
faults) in the running process, keeping its ports, link and autopilot, and answer on stdout with one line
`<the simulator's reset prefix>{json}`: its ready facts for the new world, or `{"error": "..."}`.
"""

from __future__ import annotations

import json
from typing import Any

RESET_REQUEST = "reset"


def reset_line(config: dict[str, Any]) -> bytes:
    """The stdin line asking for a reset to `config` (JSON-able)."""
    return json.dumps({RESET_REQUEST: config}).encode() + b"\n"


def reset_config(request: dict[str, Any]) -> dict[str, Any] | None:
    """The config a request asks to reset to; None if it is not a reset request."""
    config = request.get(RESET_REQUEST)
    return config if isinstance(config, dict) else None
