"""A short scripted flight in the simulated world: take off, fly a few body-velocity moves, land.

The drone flies through the autopilot and the physics only (no teleporting); the
forward camera's frames are saved as PNGs and the target's true pixel offset is
recorded with each, so a reader can see moving right shift the target left in the
image, and so on. This is the interim main command until the planner flies.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2

from drone_inspect_core.files import write_atomic
from drone_inspect_core.frames import enu_to_ned
from sim_world.world import World, WorldConfig

logger = logging.getLogger(__name__)

# (label, seconds, (forward, right, down) m/s or None for hold)
DEMO_LEGS: tuple[tuple[str, float, tuple[float, float, float] | None], ...] = (
    ("hold", 1.5, None),
    ("right", 2.0, (0.0, 0.4, 0.0)),
    ("hold", 1.0, None),
    ("left", 4.0, (0.0, -0.4, 0.0)),
    ("hold", 1.0, None),
    ("up", 1.5, (0.0, 0.0, -0.3)),
    ("down", 1.5, (0.0, 0.0, 0.3)),
    ("right", 2.0, (0.0, 0.4, 0.0)),
    ("hold", 1.0, None),
)
TAKEOFF_S = 5.0
LAND_S = 6.0


@dataclass(frozen=True)
class DemoConfig:
    out_dir: Path = Path("runs/demo")
    seconds: float = 16.0
    """Length of the scripted part (after takeoff); the legs are cut or repeated to fit."""
    frames_per_s: float = 2.0
    seed: int = 0
    world: WorldConfig = field(default_factory=WorldConfig)

    def __post_init__(self) -> None:
        if not self.seconds > 0:
            raise ValueError(f"seconds must be > 0, got {self.seconds}")
        if not 0 < self.frames_per_s <= 30:
            raise ValueError(f"frames_per_s must be in (0, 30], got {self.frames_per_s}")


@dataclass(frozen=True)
class DemoFrame:
    time_s: float
    leg: str
    image: Path
    offset_px: tuple[float, float] | None
    """(du, dv) of the target from the image centre; None when it is out of view."""
    position_ned_m: tuple[float, float, float]


@dataclass(frozen=True)
class DemoResult:
    target_kind: str
    frames: tuple[DemoFrame, ...]
    landed: bool


def _legs_for(seconds: float) -> list[tuple[str, float, tuple[float, float, float] | None]]:
    legs, left = [], seconds
    while left > 1e-9:
        for label, duration, velocity in DEMO_LEGS:
            take = min(duration, left)
            legs.append((label, take, velocity))
            left -= take
            if left <= 1e-9:
                break
    return legs


def run_demo(config: DemoConfig, on_frame: Callable[[DemoFrame], None] | None = None) -> DemoResult:
    """Fly the demo and write frames to `config.out_dir`; `on_frame` sees each saved frame."""
    config.out_dir.mkdir(parents=True, exist_ok=True)
    frames: list[DemoFrame] = []
    with World(config.world, config.seed) as world:
        ap = world.autopilot
        every = max(1, round(1.0 / (config.frames_per_s * world.dt_s)))
        lens_drop_m = -config.world.camera.offset_flu_m[2]
        altitude = float(world.scene.target_centre_enu_m[2]) + lens_drop_m - world.drone.resting_height_m
        logger.info("demo: %s target; taking off to %.2f m", world.scene.target_kind, altitude)
        ap.arm()
        world.step(2)
        ap.takeoff(altitude)
        world.run_for(TAKEOFF_S)
        for label, seconds, velocity in _legs_for(config.seconds):
            if velocity is None:
                ap.hold()
            else:
                ap.set_velocity_body(velocity[0], velocity[1], velocity[2], 0.0)
            for _ in range(round(seconds / world.dt_s)):
                world.step()
                if round(world.time_s / world.dt_s) % every == 0:
                    frame = _save_frame(world, label, config.out_dir, len(frames))
                    frames.append(frame)
                    if on_frame is not None:
                        on_frame(frame)
        ap.land()
        world.run_for(LAND_S)
        return DemoResult(world.scene.target_kind, tuple(frames), ap.landed)


def _save_frame(world: World, leg: str, out_dir: Path, number: int) -> DemoFrame:
    render = world.render(with_seg=False)
    truth = world.target_truth()
    path = out_dir / f"frame_{number:04d}.png"
    ok, png = cv2.imencode(".png", cv2.cvtColor(render.rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError(f"{path}: the frame could not be encoded as PNG")
    write_atomic(path, png.tobytes())  # whole or not at all: a full disk leaves no half frame
    n, e, d = (float(x) for x in enu_to_ned(world.state().position_enu_m))
    return DemoFrame(
        time_s=world.time_s,
        leg=leg,
        image=path,
        offset_px=truth.offset_px if truth.in_view else None,
        position_ned_m=(n, e, d),
    )
