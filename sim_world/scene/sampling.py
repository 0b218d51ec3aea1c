"""Draw one concrete scene from a `SceneConfig` and a seed: pure numbers, no PyBullet.

Each concern draws from its own random stream (`SeedSequence([seed, stream])`), so that,
for example, a different distractor count does not move the target. The wall layout is
worked out here too, in the wall's own 2-D coordinates (east, up): every item has a
rectangular footprint, and no clutter or distractor footprint may enter the target's
footprint grown by `clutter.keep_out_m`. Pipes and conduits run across the wall and may
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
from sim_world.scene.textures import TEXTURE_VARIANTS
from sim_world.scene.textures_targets import GAUGE_SCALES, SIGNS, SWITCHBOX_LABELS

logger = logging.getLogger(__name__)

PIPE_COLOURS = ("#8a8d8f", "#d4a017", "#b22222", "#2e7d32", "#1f5fa8", "#b0b4b8")
"""Industrial pipe paint (grey, gas yellow, fire red, water green, air blue, galvanised)."""
BOX_COLOURS = ("#b9bdc1", "#8f9498", "#d9d4c5", "#5d6d7e")
SWITCHBOX_ASPECTS = (1.0, 1.25, 1.5)
"""Height / width of a switch box's front."""

GAUGE_STANDOFF_M = 0.13
"""How far a gauge's dial stands off the wall (on a stem from its pipe, the case above the pipe's axis)."""
VALVE_STANDOFF_M = 0.26
"""How far a handwheel's front stands off the wall (on its stem from the valve body)."""
SWITCHBOX_DEPTH_M = 0.14
OBLIQUE_CLEARANCE = 0.6
"""An item standing further off the wall than the target's face gets this much extra
clearance per metre of extra standoff (tan 31°), so that it does not hide the target
from the oblique views of data collection."""

_STREAM_TARGET, _STREAM_SURFACES, _STREAM_LIGHT, _STREAM_CLUTTER, _STREAM_DISTRACTORS, _STREAM_NOISE = range(
    6
)
_CLUTTER_KINDS = ("pipe_h", "pipe_v", "conduit_h", "conduit_v", "junction_box", "bracket", "sign")
_CLUTTER_WEIGHTS = (0.18, 0.12, 0.12, 0.1, 0.2, 0.1, 0.18)
_MAX_CLUTTER = 12
_TRIES = 40
_LINEAR = {"pipe_h": "h", "conduit_h": "h", "pipe_v": "v", "conduit_v": "v"}


@dataclass(frozen=True)
class TargetParams:
    """The sampled target. Kind-specific fields are drawn for every kind (so the stream
    stays aligned) and only used by their kind."""

    kind: str
    size_m: float
    """Diameter (gauge, valve handwheel) or width (switch box) of the front face."""
    face_height_m: float
    east_m: float
    height_m: float
    dial_colour: str
    bezel_colour: str
    needle_fraction: float
    gauge_scale: int
    red_zone: bool
    red_needle: bool
    mount_drop_m: float
    """Gauge: length of the stem down to its process pipe."""
    mount_variant: int
    """Where the flanges on the target's pipe sit."""
    spokes: int
    """Valve: handwheel spokes."""
    label_index: int
    label_number: int
    switches: tuple[int, ...]
    lights: tuple[int, ...]


@dataclass(frozen=True)
class WallItem:
    """Something on the wall: its kind, footprint centre and size in the wall plane, standoff."""

    kind: str
    east_m: float
    up_m: float
    width_m: float
    height_m: float
    standoff_m: float
    """How far its front stands out from the wall."""
    colour: str
    variant: int = 0

    def footprint(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """(east0, up0, east1, up1) in the wall plane, grown by `margin_m`."""
        hw, hh = self.width_m / 2 + margin_m, self.height_m / 2 + margin_m
        return self.east_m - hw, self.up_m - hh, self.east_m + hw, self.up_m + hh


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
    """What holds the target (see `mounts_for`)."""
    clutter: tuple[WallItem, ...]
    distractors: tuple[WallItem, ...]

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


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1])) if bounds[1] > bounds[0] else float(bounds[0])


def _pick(rng: np.random.Generator, options: tuple) -> object:
    return options[int(rng.integers(0, len(options)))]


def sample_target(config: SceneConfig, rng: np.random.Generator) -> TargetParams:
    cfg = config.target
    kind = str(_pick(rng, cfg.kinds))
    size = _uniform(rng, cfg.size_m)
    aspect = float(_pick(rng, SWITCHBOX_ASPECTS))
    face_height = size * aspect if kind == "switchbox" else size
    height = _uniform(rng, cfg.height_m)
    # The wall must hold the target (and a gauge's stem and pipe below it).
    height = float(np.clip(height, face_height / 2 + 0.5, config.wall.height_m - face_height / 2 - 0.2))
    needle_fraction = round(_uniform(rng, cfg.needle_fraction) * 200) / 200  # a finite set of dial textures
    return TargetParams(
        kind=kind,
        size_m=size,
        face_height_m=face_height,
        east_m=_uniform(rng, cfg.east_m),
        height_m=height,
        dial_colour=str(_pick(rng, cfg.dial_colours)),
        bezel_colour=str(_pick(rng, cfg.bezel_colours)),
        needle_fraction=needle_fraction,
        gauge_scale=int(rng.integers(0, len(GAUGE_SCALES))),
        red_zone=bool(rng.random() < 0.6),
        red_needle=bool(rng.random() < 0.4),
        mount_drop_m=float(rng.uniform(0.22, 0.4)),
        mount_variant=int(rng.integers(0, 1000)),
        spokes=int(rng.integers(3, 6)),
        label_index=int(rng.integers(0, len(SWITCHBOX_LABELS))),
        label_number=int(rng.integers(1, 40)),
        switches=tuple(int(s) for s in rng.integers(0, 2, size=int(rng.integers(1, 4)))),
        lights=tuple(int(s) for s in rng.integers(0, 3, size=int(rng.integers(1, 4)))),
    )


def target_footprint(target: TargetParams) -> tuple[float, float, float, float]:
    """(east0, up0, east1, up1) of the target's front face in the wall plane."""
    hw, hh = target.size_m / 2, target.face_height_m / 2
    return target.east_m - hw, target.height_m - hh, target.east_m + hw, target.height_m + hh


def target_standoff_m(target: TargetParams) -> float:
    """How far the target's face stands off the wall."""
    return {"gauge": GAUGE_STANDOFF_M, "valve": VALVE_STANDOFF_M}.get(target.kind, SWITCHBOX_DEPTH_M)


def rects_overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> bool:
    """Whether two (x0, y0, x1, y1) rectangles share interior points."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


class _Layout:
    """Rejection-sampling placement on the wall, keeping the target's surroundings clear."""

    def __init__(self, config: SceneConfig, target: TargetParams, mounts: tuple[WallItem, ...]) -> None:
        self.config = config
        self.target = target
        keep = config.clutter.keep_out_m
        x0, z0, x1, z1 = target_footprint(target)
        self.keep_out = (x0 - keep, z0 - keep, x1 + keep, z1 + keep)
        self.placed: list[WallItem] = list(mounts)

    def fits(self, item: WallItem) -> bool:
        gap = 0.03
        extra = OBLIQUE_CLEARANCE * max(0.0, item.standoff_m - target_standoff_m(self.target))
        x0, z0, x1, z1 = self.keep_out
        if rects_overlap(item.footprint(), (x0 - extra, z0 - extra, x1 + extra, z1 + extra)):
            return False
        w, h = self.config.wall.width_m, self.config.wall.height_m
        x0, z0, x1, z1 = item.footprint()
        if x0 < -w / 2 or x1 > w / 2 or z0 < 0.0 or z1 > h:
            return False
        for other in self.placed:
            crossing = (
                item.kind in _LINEAR and other.kind in _LINEAR and _LINEAR[item.kind] != _LINEAR[other.kind]
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


def mounts_for(target: TargetParams, config: SceneConfig) -> tuple[WallItem, ...]:
    """What holds the target: a gauge's process pipe, a valve's pipe, a switch box's conduit.

    They touch or pass behind the target by design, so they are laid out first and
    exempt from the keep-out rule (they never stand in front of the target's face).
    """
    w, h = config.wall.width_m, config.wall.height_m
    t = target
    if t.kind == "gauge":
        up = t.height_m - t.face_height_m / 2 - t.mount_drop_m
        return (WallItem("pipe_h", 0.0, up, w, 0.14, 0.13, "#8a8d8f", t.mount_variant),)
    if t.kind == "valve":
        return (WallItem("pipe_h", 0.0, t.height_m, w, 0.16, 0.14, "#8a8d8f", t.mount_variant),)
    top = t.height_m + t.face_height_m / 2
    return (WallItem("conduit_v", t.east_m, (top + h) / 2, 0.05, h - top, 0.05, "#b0b4b8"),)


def _propose_clutter(
    kind: str, rng: np.random.Generator, config: SceneConfig, target: TargetParams
) -> WallItem:
    w, h = config.wall.width_m, config.wall.height_m
    near_east = target.east_m + float(rng.uniform(-2.5, 2.5))
    up = float(rng.uniform(0.3, h - 0.3))
    colour = str(_pick(rng, PIPE_COLOURS))
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
            kind, near_east, up, bw, bh, float(rng.uniform(0.06, 0.12)), str(_pick(rng, BOX_COLOURS))
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
        colour = str(_pick(rng, config.target.dial_colours))  # the colour of a switch box: a hard negative
        return WallItem("box", east, up, size, size * float(rng.uniform(0.8, 1.4)), 0.12, colour)
    return WallItem("round_sign", east, up, size, size, 0.01, "#ffffff", variant=int(rng.integers(0, 2)))


def sample_scene(config: SceneConfig, seed: int) -> SceneParams:
    """One scene of the family `config`, fully determined by `seed`."""
    target = sample_target(config, _rng(seed, _STREAM_TARGET))

    srng = _rng(seed, _STREAM_SURFACES)
    wall = (str(_pick(srng, config.wall.textures)), str(_pick(srng, config.wall.colours)))
    wall_variant = int(srng.integers(0, TEXTURE_VARIANTS))
    floor = (str(_pick(srng, config.floor.textures)), str(_pick(srng, config.floor.colours)))
    floor_variant = int(srng.integers(0, TEXTURE_VARIANTS))

    lrng, light = _rng(seed, _STREAM_LIGHT), config.lighting
    lighting = LightingParams(
        azimuth_deg=_uniform(lrng, light.azimuth_deg),
        elevation_deg=_uniform(lrng, light.elevation_deg),
        intensity=_uniform(lrng, light.intensity),
        ambient=_uniform(lrng, light.ambient),
        diffuse=_uniform(lrng, light.diffuse),
        specular=_uniform(lrng, light.specular),
        shadow=light.shadow,
    )

    mounts = mounts_for(target, config)
    layout = _Layout(config, target, mounts)
    crng = _rng(seed, _STREAM_CLUTTER)
    density = _uniform(crng, config.clutter.density)
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
        kind = str(_pick(drng, config.clutter.distractor_kinds))
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
        camera_noise_std=_uniform(_rng(seed, _STREAM_NOISE), config.camera_noise_std),
        clutter_density=density,
        mounts=mounts,
        clutter=tuple(clutter),
        distractors=tuple(distractors),
    )
