"""The ArduPilot simulator as a process: its config as JSON, and `serve` (signals, parent watch, ready line).

`python -m sim_world.ardupilot_bridge --config FILE.json` (what the `ardupilot-sitl` mission kit and
`dronectl bench ardupilot` start) and `dronectl ardupilot-sim` (a person's terminal) both end in `serve`.
"""

from __future__ import annotations

import logging
from typing import TextIO

from sim_world.ardupilot_bridge.ardupilot_process import ArduPilotStartError
from sim_world.ardupilot_bridge.bridge import ArduPilotRestartedError
from sim_world.ardupilot_bridge.link import ArduPilotSilentError, PhysicsLinkError
from sim_world.ardupilot_bridge.run import ArduPilotSimConfig, run_ardupilot_sim
from sim_world.process_entry import LauncherRequests, say_ready, stop_on_signals
from sim_world.process_entry import watch_parent as parent_watch
from sim_world.rendering.video import VideoError

log = logging.getLogger(__name__)

READY_PREFIX = "ardupilot-sim ready: "
RESET_PREFIX = "ardupilot-sim reset: "
"""A warm simulator's answer to a reset: the ready facts, or `{"error": ...}`."""


def serve(
    config: ArduPilotSimConfig,
    out: TextIO,
    watch_parent: bool = False,
    requests: LauncherRequests | None = None,
) -> int:
    """Run until SIGINT, SIGTERM, SIGHUP (or the parent's death, with `watch_parent`); an exit code.

    Prints one line `ardupilot-sim ready: {json}` to `out` once ArduPilot's first physics frame is
    answered (URLs, ArduPilot's system id), and a summary at the end. 0: stopped as asked; 1: ArduPilot
    or the simulator failed (the reason is logged and printed).
    """
    stop = stop_on_signals("ardupilot-sim")
    if watch_parent:
        parent_watch(stop, "ardupilot-sim")
    try:
        stats = run_ardupilot_sim(
            config,
            stop,
            on_ready=lambda info: say_ready(out, READY_PREFIX, info),
            requests=requests,
            on_reset=lambda info, error: say_ready(out, RESET_PREFIX, {"error": error} if error else info),
        )
    except (ArduPilotStartError, ArduPilotSilentError, ArduPilotRestartedError, PhysicsLinkError, VideoError,
            OSError) as exc:  # fmt: skip
        log.error("ardupilot-sim: %s", exc)
        out.write(f"ardupilot-sim failed: {exc}\n")
        out.flush()
        return 1
    out.write(
        f"ardupilot-sim: {stats.sim_s:.1f} s simulated in {stats.wall_s:.1f} s "
        f"(x{stats.real_time_factor:.2f}), "
        f"{stats.frames} physics frames, {stats.repeats} repeated, {stats.camera_frames} camera frames\n"
    )
    out.flush()
    return 0
