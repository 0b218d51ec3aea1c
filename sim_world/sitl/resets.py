"""A warm SITL simulator's resets: the next mission's world behind the running autopilot.

Both bridges (PX4's, ArduPilot's) keep their autopilot between the missions of one process (a
benchmark's worker). A reset request (`drone_inspect_core.launcher_requests`) carries the simulator's whole
config; only the world in it may differ (`WORLD_FIELDS`: scene, seed, start, wind, camera faults), since
the autopilot's process, ports, parameters and sensors stay. The world is built fresh, as at start; the
bridge flies it from its next tick through an `AutopilotFrame` that continues what the autopilot saw
(`rebase`), the camera shows it, and the old world is closed.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from drone_inspect_core.config_files import from_json
from drone_inspect_core.launcher_requests import reset_config
from sim_world.process_entry import LauncherRequests
from sim_world.rendering.video import WorldVideoFeed
from sim_world.world import World

log = logging.getLogger(__name__)

WORLD_FIELDS = ("scene", "seed", "start_offset", "wind", "video_faults")
"""The fields of a SITL simulator's config that a reset may change: its world."""

ConfigT = TypeVar("ConfigT")


class Rebasable(Protocol):
    def rebase(self, world: World, origin_enu_m: np.ndarray) -> None: ...


class SitlResets(Generic[ConfigT]):
    """The world flown now (`world`, built from `config`), and the resets that replace it."""

    def __init__(self, config: ConfigT, build: Callable[[ConfigT], World]) -> None:
        self.config, self._build = config, build
        self.world = build(config)

    def take(
        self, requests: LauncherRequests, bridge: Rebasable, video: WorldVideoFeed | None
    ) -> str | bool | None:
        """Carry out the launcher's next request: False when there is none; None when its world flies
        from the bridge's next tick; else why it cannot (the old world flies on)."""
        request = requests.take()
        if request is None:
            return False
        try:
            data = reset_config(request)
            if data is None:
                raise ValueError(f"not a request this simulator knows: {sorted(request)}")
            config: Any = from_json(type(self.config), data)
            same_world = {name: getattr(self.config, name) for name in WORLD_FIELDS}
            if replace(config, **same_world) != self.config:
                raise ValueError(f"a reset may change the world ({', '.join(WORLD_FIELDS)}) alone")
            world = self._build(config)
        except (ValueError, KeyError, TypeError) as exc:
            return f"bad reset request: {exc}"
        origin = world.state().position_enu_m.copy()
        bridge.rebase(world, origin)
        self.world.close()
        self.world, self.config = world, config
        if video is not None:
            video.reset(world, origin, config.video_faults)  # a VideoError ends the process
        log.info("reset: a new world (seed %d) behind the autopilot", config.seed)
        return None

    def close(self) -> None:
        self.world.close()
