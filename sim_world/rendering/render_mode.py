"""How the flight camera is rendered: inline in the physics process, or by render workers.

`CameraFeed(mode, ...)` renders the camera at its rate in either mode:

- `single`: `World.render` in the physics process, between physics steps;
- `workers`: `RenderWorkers` mirror the world in other processes, so frames render
  while the physics runs on (they win when there is a core to spare, and lose
  when other work already holds the cores: then they only add copying and waiting).

Which is faster depends on the machine and on what else runs on it, so `auto` (the
default) measures it: `calibrate` flies a short hover with the camera on in each mode
(about a second of wall time each, after the workers are up) and `choose_render_mode`
keeps the faster. The measurement is a function argument, so tests inject it; an
explicit `single` or `workers` skips the calibration.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from types import TracebackType
from typing import Any

from sim_world.rendering.render_workers import RenderWorkers
from sim_world.world import World, WorldConfig

logger = logging.getLogger(__name__)

RENDER_MODES = ("auto", "single", "workers")
CONCRETE_MODES = ("single", "workers")


class CameraFeed:
    """Render the camera of `world` in `mode` ("single" or "workers"); `tick()` at each camera time.

    `frames` counts the frames in hand; `drain()` collects the ones still rendering.
    """

    def __init__(self, mode: str, config: WorldConfig, seed: int, workers: int = 2) -> None:
        if mode not in CONCRETE_MODES:
            raise ValueError(f"render mode must be one of {CONCRETE_MODES}, got {mode!r}")
        self.mode = mode
        self.frames = 0
        self._workers = workers
        self._pool = RenderWorkers(config, seed, workers) if mode == "workers" else None

    def tick(self, world: World) -> None:
        """Render (single) or request (workers: collecting the oldest frame when all are busy) a frame."""
        if self._pool is None:
            world.render(with_seg=False)
            self.frames += 1
            return
        if self._pool.outstanding == self._workers:
            self._pool.collect()
            self.frames += 1
        self._pool.submit(world.state(), noise_seed=int(world.noise_rng.integers(2**31)))

    def drain(self) -> None:
        while self._pool is not None and self._pool.outstanding:
            self._pool.collect()
            self.frames += 1

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()

    def __enter__(self) -> CameraFeed:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def hover_rtf(world: World, feed: CameraFeed, sim_s: float, camera_hz: float) -> float:
    """Real-time factor of `sim_s` of hovering with `feed` rendering at `camera_hz` (frames drained)."""
    every = max(1, round(1.0 / (camera_hz * world.dt_s)))
    steps = max(every, round(sim_s / world.dt_s))
    start = time.perf_counter()
    for step in range(1, steps + 1):
        world.step()
        if step % every == 0:
            feed.tick(world)
    feed.drain()
    return steps * world.dt_s / (time.perf_counter() - start)


def calibrate(
    config: WorldConfig, seed: int, sim_s: float = 2.0, camera_hz: float = 30.0, workers: int = 2
) -> dict[str, float]:
    """Each mode's real-time factor over `sim_s` of hovering with the camera on (after a warm-up)."""
    rtf: dict[str, float] = {}
    with World(config, seed) as world:
        position, yaw = world.scene.pose_for_offset(0.0, 0.0, 2.0, 0.0)
        world.teleport(position, yaw)
        for mode in CONCRETE_MODES:
            with CameraFeed(mode, config, seed, workers) as feed:
                hover_rtf(world, feed, 4 * workers / camera_hz, camera_hz)  # warm-up: texture upload
                rtf[mode] = hover_rtf(world, feed, sim_s, camera_hz)
    return rtf


@dataclass(frozen=True)
class RenderModeChoice:
    """The mode to render in, what was asked, and why."""

    mode: str
    requested: str
    reason: str
    calibration_rtf: dict[str, float] | None
    load_avg_1min: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def choose_render_mode(requested: str, measure: Callable[[], dict[str, float]]) -> RenderModeChoice:
    """`requested` as it is, or for "auto" the mode of highest real-time factor by `measure()`.

    `measure` is `calibrate` bound to a world config in use, or a stand-in in tests.
    """
    if requested not in RENDER_MODES:
        raise ValueError(f"render mode must be one of {RENDER_MODES}, got {requested!r}")
    load = os.getloadavg()[0]
    if requested != "auto":
        logger.info("render mode %s (explicit)", requested)
        return RenderModeChoice(requested, requested, "explicit", None, load)
    rtf = measure()
    missing = set(CONCRETE_MODES) - set(rtf)
    if missing:
        raise ValueError(f"render-mode calibration gave no figure for {sorted(missing)}: {rtf}")
    mode = max(CONCRETE_MODES, key=lambda m: rtf[m])
    reason = "calibrated: " + ", ".join(f"{m} {rtf[m]:.2f}x real time" for m in CONCRETE_MODES)
    reason += f" at load average {load:.2f} on {os.cpu_count()} CPUs"
    logger.info("render mode %s (%s)", mode, reason)
    return RenderModeChoice(mode, requested, reason, dict(rtf), load)
