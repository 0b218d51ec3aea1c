"""Draw one concrete scene from a `SceneConfig` and a seed: pure numbers, no PyBullet.

Each concern draws from its own random stream (`SeedSequence([seed, stream])`), so that,
for example, a different distractor count does not move the target. The wall layout is
worked out here too, in the wall's own 2-D coordinates (east, up): every item has a
rectangular footprint, and no clutter or distractor footprint may enter the target's
footprint grown by `clutter.keep_out_m` (every target's, in a scene of several:
`sampling_targets` draws them). Pipes and conduits run across the wall and may
cross each other (they stand off the wall by different amounts); compact items (boxes,
signs, brackets, distractors) overlap nothing.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from sim_world.scene.config import SceneConfig
from sim_world.scene.sampling_targets import (
    GAUGE_STANDOFF_M,
    LINEAR,
    SWITCHBOX_ASPECTS,
    SWITCHBOX_DEPTH_M,
    VALVE_STANDOFF_M,
    SceneLayoutError,
    TargetParams,
    WallItem,
    mounts_for,
    pick,
    rects_overlap,
    sample_target,
    sample_targets,
    target_footprint,
    target_standoff_m,
    uniform,
)
from sim_world.scene.textures import TEXTURE_VARIANTS
from sim_world.scene.textures_targets import SIGNS

__all__ = [  # the target's pieces live in sampling_targets; re-exported for the scene's other modules
    "GAUGE_STANDOFF_M",
    "SWITCHBOX_ASPECTS",
    "SWITCHBOX_DEPTH_M",
    "VALVE_STANDOFF_M",
    "LightingParams",
    "SceneLayoutError",
    "SceneParams",
    "TargetParams",
    "WallItem",
    "mounts_for",
    "rects_overlap",
    "sample_scene",
    "sample_target",
    "target_footprint",
    "target_standoff_m",
]

logger = logging.getLogger(__name__)

PIPE_COLOURS = ("#8a8d8f", "#d4a017", "#b22222", "#2e7d32", "#1f5fa8", "#b0b4b8")
"""Industrial pipe paint (grey, gas yellow, fire red, water green, air blue, galvanised)."""
BOX_COLOURS = ("#b9bdc1", "#8f9498", "#d9d4c5", "#5d6d7e")
OBLIQUE_CLEARANCE = 0.6
"""An item standing further off the wall than the target's face gets this much extra
clearance per metre of extra standoff (tan 31°), so that it does not hide the target
from the oblique views of data collection."""

_STREAM_TARGET, _STREAM_SURFACES, _STREAM_LIGHT, _STREAM_CLUTTER, _STREAM_DISTRACTORS, _STREAM_NOISE = range(
    6
)
_STREAM_OTHER_TARGETS = 6
"""The targets beside the named one (and every target's local mount): a stream added last, so
that a single-target scene draws exactly what it always did."""
_CLUTTER_KINDS = ("pipe_h", "pipe_v", "conduit_h", "conduit_v", "junction_box", "bracket", "sign")
_CLUTTER_WEIGHTS = (0.18, 0.12, 0.12, 0.1, 0.2, 0.1, 0.18)
_MAX_CLUTTER = 12
_TRIES = 40


@dataclass(frozen=True)
class LightingParams:
    azimuth_deg: float
    elevation_deg: float
    intensity: float
    ambient: float
    diffuse: float
    specular: float
    shadow: bool

    def direction_enu(self) -> tuple[float, float, float]:
        """Unit vector towards the light (what TinyRenderer's `lightDirection` means)."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)


@dataclass(frozen=True)
class SceneParams:
    """Everything one scene is built from."""

    seed: int
    target: TargetParams
    wall_texture: str
    wall_colour: str
    wall_variant: int
    floor_texture: str
    floor_colour: str
    floor_variant: int
    lighting: LightingParams
    camera_noise_std: float
    clutter_density: float
    mounts: tuple[WallItem, ...]
    """What holds the targets (see `mounts_for`): the named one's first."""
    clutter: tuple[WallItem, ...]
    distractors: tuple[WallItem, ...]
    others: tuple[TargetParams, ...] = ()
    """The targets beside the named one (`target`), when `target.count` drew more than one."""

    @property
    def targets(self) -> tuple[TargetParams, ...]:
        """Every target, the named one first."""
        return (self.target, *self.others)

    def as_dict(self) -> dict:
        """JSON-able (tuples become lists, floats rounded to 4 decimals for a readable manifest)."""
        return _rounded(asdict(self))


def _rounded(value: object) -> object:
    if isinstance(value, float):
        return round(value, 4)
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_rounded(v) for v in value]
    return value


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, stream]))


class _Layout:
    """Rejection-sampling placement on the wall, keeping every target's surroundings clear."""

    def __init__(
        self, config: SceneConfig, targets: tuple[TargetParams, ...], mounts: tuple[WallItem, ...]
    ) -> None:
        self.config = config
        keep = config.clutter.keep_out_m
        self.keep_outs = [(target_footprint(t, keep), target_standoff_m(t)) for t in targets]
        """Each target's footprint grown by the keep-out, and how far its face stands off the wall."""
        self.placed: list[WallItem] = list(mounts)

    def fits(self, item: WallItem) -> bool:
        gap = 0.03
        for (x0, z0, x1, z1), standoff in self.keep_outs:
            extra = OBLIQUE_CLEARANCE * max(0.0, item.standoff_m - standoff)
            if rects_overlap(item.footprint(), (x0 - extra, z0 - extra, x1 + extra, z1 + extra)):
                return False
        w, h = self.config.wall.width_m, self.config.wall.height_m
        x0, z0, x1, z1 = item.footprint()
        if x0 < -w / 2 or x1 > w / 2 or z0 < 0.0 or z1 > h:
            return False
        for other in self.placed:
            crossing = (
                item.kind in LINEAR and other.kind in LINEAR and LINEAR[item.kind] != LINEAR[other.kind]
            )
            if not crossing and rects_overlap(item.footprint(gap), other.footprint()):
                return False
        return True

    def place(self, propose: Callable[[], WallItem]) -> WallItem | None:
        """Try `propose()` until an item fits (then keep it) or the tries run out."""
        for _ in range(_TRIES):
            item = propose()
            if self.fits(item):
                self.placed.append(item)
                return item
        return None


def _propose_clutter(
    kind: str, rng: np.random.Generator, config: SceneConfig, target: TargetParams
) -> WallItem:
    w, h = config.wall.width_m, config.wall.height_m
    near_east = target.east_m + float(rng.uniform(-2.5, 2.5))
    up = float(rng.uniform(0.3, h - 0.3))
    colour = str(pick(rng, PIPE_COLOURS))
    if kind == "pipe_h":
        d = float(rng.uniform(0.08, 0.2))
        return WallItem(kind, 0.0, up, w, d * 1.4, d + 0.03, colour, variant=int(rng.integers(0, 1000)))
    if kind == "pipe_v":
        d = float(rng.uniform(0.08, 0.18))
        return WallItem(
            kind, near_east, h / 2, d * 1.4, h, d + 0.24, colour, variant=int(rng.integers(0, 1000))
        )
    if kind == "conduit_h":
        length = float(rng.uniform(1.0, 4.0))
        return WallItem(kind, near_east, up, length, 0.04, 0.05, "#b0b4b8")
    if kind == "conduit_v":
        length = float(rng.uniform(0.8, 2.5))
        return WallItem(kind, near_east, up, 0.04, length, 0.05, "#b0b4b8")
    if kind == "junction_box":
        bw, bh = float(rng.uniform(0.12, 0.3)), float(rng.uniform(0.12, 0.3))
        return WallItem(
            kind, near_east, up, bw, bh, float(rng.uniform(0.06, 0.12)), str(pick(rng, BOX_COLOURS))
        )
    if kind == "bracket":
        return WallItem(kind, near_east, up, 0.06, float(rng.uniform(0.15, 0.3)), 0.08, "#3c3f42")
    sign_w = float(rng.uniform(0.3, 0.5))
    return WallItem(
        "sign", near_east, up, sign_w, sign_w / 2, 0.01, "#ffffff", variant=int(rng.integers(0, len(SIGNS)))
    )


def _propose_distractor(
    kind: str, rng: np.random.Generator, config: SceneConfig, target: TargetParams
) -> WallItem:
    size = target.size_m * float(rng.uniform(0.6, 1.1))
    east = target.east_m + float(rng.uniform(-1.8, 1.8))
    up = float(np.clip(target.height_m + rng.uniform(-0.9, 0.9), 0.4, config.wall.height_m - 0.4))
    if kind == "dial":
        return WallItem("dial", east, up, size, size, 0.06, "#e67e22", variant=int(rng.integers(0, 100)))
    if kind == "box":
        colour = str(pick(rng, config.target.dial_colours))  # the colour of a switch box: a hard negative
        return WallItem("box", east, up, size, size * float(rng.uniform(0.8, 1.4)), 0.12, colour)
    return WallItem("round_sign", east, up, size, size, 0.01, "#ffffff", variant=int(rng.integers(0, 2)))


def sample_scene(config: SceneConfig, seed: int) -> SceneParams:
    """One scene of the family `config`, fully determined by `seed`."""
    target = sample_target(config, _rng(seed, _STREAM_TARGET))

    srng = _rng(seed, _STREAM_SURFACES)
    wall = (str(pick(srng, config.wall.textures)), str(pick(srng, config.wall.colours)))
    wall_variant = int(srng.integers(0, TEXTURE_VARIANTS))
    floor = (str(pick(srng, config.floor.textures)), str(pick(srng, config.floor.colours)))
    floor_variant = int(srng.integers(0, TEXTURE_VARIANTS))

    lrng, light = _rng(seed, _STREAM_LIGHT), config.lighting
    lighting = LightingParams(
        azimuth_deg=uniform(lrng, light.azimuth_deg),
        elevation_deg=uniform(lrng, light.elevation_deg),
        intensity=uniform(lrng, light.intensity),
        ambient=uniform(lrng, light.ambient),
        diffuse=uniform(lrng, light.diffuse),
        specular=uniform(lrng, light.specular),
        shadow=light.shadow,
    )

    others, mounts = sample_targets(config, target, _rng(seed, _STREAM_OTHER_TARGETS), seed)
    layout = _Layout(config, (target, *others), mounts)
    crng = _rng(seed, _STREAM_CLUTTER)
    density = uniform(crng, config.clutter.density)
    clutter: list[WallItem] = []
    for _ in range(round(density * _MAX_CLUTTER)):
        kind = str(crng.choice(_CLUTTER_KINDS, p=_CLUTTER_WEIGHTS))
        item = layout.place(lambda k=kind: _propose_clutter(k, crng, config, target))
        if item is not None:
            clutter.append(item)

    drng = _rng(seed, _STREAM_DISTRACTORS)
    lo, hi = config.clutter.distractors
    distractors: list[WallItem] = []
    for _ in range(int(drng.integers(lo, hi + 1))):
        kind = str(pick(drng, config.clutter.distractor_kinds))
        item = layout.place(lambda k=kind: _propose_distractor(k, drng, config, target))
        if item is None:
            logger.debug("scene %d: no room for a %s distractor", seed, kind)
        else:
            distractors.append(item)

    return SceneParams(
        seed=seed,
        target=target,
        wall_texture=wall[0],
        wall_colour=wall[1],
        wall_variant=wall_variant,
        floor_texture=floor[0],
        floor_colour=floor[1],
        floor_variant=floor_variant,
        lighting=lighting,
        camera_noise_std=uniform(_rng(seed, _STREAM_NOISE), config.camera_noise_std),
        clutter_density=density,
        mounts=mounts,
        clutter=tuple(clutter),
        distractors=tuple(distractors),
        others=others,
    )
