"""The PX4 simulator's process entry point: `python -m sim_world.px4_bridge --config FILE.json`.

What launchers start (the `px4-sitl` mission kit): the config is `run.config_to_json`'s
form of a `Px4SimConfig`, so nothing is parsed twice. It watches its parent and stops
(PX4 included) when the parent is gone. People use `dronectl px4-sim`.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from sim_world.px4_bridge.run import config_from_json, serve


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != "--config":
        print("usage: python -m sim_world.px4_bridge --config FILE.json", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        config = config_from_json(json.loads(Path(argv[1]).read_text()))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"px4-sim: bad config {argv[1]}: {exc}", file=sys.stderr)
        return 2
    return serve(config, sys.stdout, watch_parent=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
