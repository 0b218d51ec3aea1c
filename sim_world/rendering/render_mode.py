"""How the flight camera is rendered: inline in the physics process, or by render workers.

`CameraFeed(mode, ...)` renders the camera at its rate in either mode:

- `single`: `World.render` in the physics process, between physics steps;
- `workers`: `RenderWorkers` mirror the world in other processes, so frames render
  while the physics runs on.

Which is faster depends on the machine and on what else runs on it: the workers overlap
rendering with the physics when a core is free; with the cores partly taken the copying
and waiting can cost more than the overlap gives; with them fully taken three processes
get a larger share of the CPU than one (README: the measured table). So `auto`
(the default) measures it: `calibrate` hovers with the camera on in each mode, in turns
(about two seconds of wall time in all at 3x real time, after the workers are up), and
`choose_render_mode` keeps the faster (the workers only by a 5 % margin). The
measurement is a function argument, so tests inject it; an explicit `single` or
`workers` skips the calibration.
"""

from __future__ import annotations

import contextlib
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
WORKERS_MARGIN = 1.05
"""`auto` takes the workers only when they calibrate at least 5 % faster: within the noise of
a short calibration the single process is the simpler choice (no extra processes)."""


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
    config: WorldConfig,
    seed: int,
    sim_s: float = 1.5,
    camera_hz: float = 30.0,
    workers: int = 2,
    rounds: int = 2,
) -> dict[str, float]:
    """Each mode's mean real-time factor over `rounds` of `sim_s` hovering with the camera on.

    The modes take turns (single, workers, then workers, single, …) after a warm-up, so a
    change in the machine's other load during the calibration weighs on both alike.
    """
    runs: dict[str, list[float]] = {mode: [] for mode in CONCRETE_MODES}
    with contextlib.ExitStack() as stack:
        world = stack.enter_context(World(config, seed))
        position, yaw = world.scene.pose_for_offset(0.0, 0.0, 2.0, 0.0)
        world.teleport(position, yaw)
        feeds = {
            mode: stack.enter_context(CameraFeed(mode, config, seed, workers)) for mode in CONCRETE_MODES
        }
        for feed in feeds.values():
            hover_rtf(world, feed, 4 * workers / camera_hz, camera_hz)  # warm-up: texture upload
        for r in range(rounds):
            for mode in CONCRETE_MODES if r % 2 == 0 else CONCRETE_MODES[::-1]:
                runs[mode].append(hover_rtf(world, feeds[mode], sim_s, camera_hz))
    return {mode: sum(values) / len(values) for mode, values in runs.items()}


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
    """`requested` as it is, or for "auto" the faster mode by `measure()` (workers by `WORKERS_MARGIN`).

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
    mode = "workers" if rtf["workers"] > WORKERS_MARGIN * rtf["single"] else "single"
    reason = "calibrated: " + ", ".join(f"{m} {rtf[m]:.2f}x real time" for m in CONCRETE_MODES)
    reason += f" at load average {load:.2f} on {os.cpu_count()} CPUs"
    logger.info("render mode %s (%s)", mode, reason)
    return RenderModeChoice(mode, requested, reason, dict(rtf), load)
