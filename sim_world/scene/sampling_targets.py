"""Drawing the inspection targets: the named one, the others beside it, and what holds each.

The named target (the one an instruction asks to centre) is drawn from the scene's
target stream exactly as a single-target scene always was. With `target.count` above
one, the other targets are drawn from a stream of their own (so nothing else in the
scene moves), beside the named one so that all are in view from its centred pose,
with kinds distinct where `other_kinds` allows and, for two of one kind, trim colours
of different names (`drone_inspect_core.vocabulary.colour_name`): the attribute an instruction names.
Every target then gets a local mount (a short pipe, or a switch box's conduit), so the
named one is not told by its mount; no mount crosses another target's face.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drone_inspect_core.vocabulary import colour_name
from sim_world.scene.config import SceneConfig
from sim_world.scene.textures_targets import GAUGE_SCALES, SWITCHBOX_LABELS

SWITCHBOX_ASPECTS = (1.0, 1.25, 1.5)
"""Height / width of a switch box's front."""
GAUGE_STANDOFF_M = 0.13
"""How far a gauge's dial stands off the wall (on a stem from its pipe, the case above the pipe's axis)."""
VALVE_STANDOFF_M = 0.26
"""How far a handwheel's front stands off the wall (on its stem from the valve body)."""
SWITCHBOX_DEPTH_M = 0.14
IMAGE_PANEL_STANDOFF_M = 0.02
"""A kind drawn as a picture (`Face.image`) is a thin panel fastened this far off the wall."""
MOUNT_PIPE_COLOUR = "#8a8d8f"

OTHER_EAST_M = (0.45, 1.2)
"""How far (either side) another target's centre stands east or west of the named one's."""
OTHER_UP_M = 0.6
"""Another target's centre is at most this much above or below the named one's."""
LOCAL_PIPE_M = (0.6, 1.4)
"""Length of a gauge's or valve's pipe segment in a scene of several targets."""
_PLACE_TRIES = 40
_LAYOUT_TRIES = 25


class SceneLayoutError(RuntimeError):
    """The other targets could not be placed beside the named one (the message names the seed)."""


@dataclass(frozen=True)
class TargetParams:
    """A sampled target. Kind-specific fields are drawn for every kind (so the stream
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


LINEAR = {"pipe_h": "h", "conduit_h": "h", "pipe_v": "v", "conduit_v": "v"}
"""Items that run across the wall, by direction: a horizontal one may cross a vertical one."""


def uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1])) if bounds[1] > bounds[0] else float(bounds[0])


def pick(rng: np.random.Generator, options: tuple) -> object:
    return options[int(rng.integers(0, len(options)))]


def sample_target(
    config: SceneConfig, rng: np.random.Generator, kind: str | None = None, bezel_colour: str | None = None
) -> TargetParams:
    """A target drawn from `config.target`; `kind` / `bezel_colour` given: those instead of a draw
    (the named target leaves both None, which is the single-target draw unchanged)."""
    cfg = config.target
    kind = str(pick(rng, cfg.kinds)) if kind is None else kind
    size = uniform(rng, cfg.size_m)
    aspect = float(pick(rng, SWITCHBOX_ASPECTS))
    face_height = size * aspect if kind == "switchbox" else size
    panel = image_size_m(config, kind)
    if panel is not None:  # a picture keeps its own size (the draws above keep the stream aligned)
        size, face_height = panel
    height = uniform(rng, cfg.height_m)
    # The wall must hold the target (and a gauge's stem and pipe below it).
    height = float(np.clip(height, face_height / 2 + 0.5, config.wall.height_m - face_height / 2 - 0.2))
    needle_fraction = round(uniform(rng, cfg.needle_fraction) * 200) / 200  # a finite set of dial textures
    return TargetParams(
        kind=kind,
        size_m=size,
        face_height_m=face_height,
        east_m=uniform(rng, cfg.east_m),
        height_m=height,
        dial_colour=str(pick(rng, cfg.dial_colours)),
        bezel_colour=str(pick(rng, cfg.named_bezel_colours())) if bezel_colour is None else bezel_colour,
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


def target_footprint(target: TargetParams, margin_m: float = 0.0) -> tuple[float, float, float, float]:
    """(east0, up0, east1, up1) of the target's front face in the wall plane, grown by `margin_m`."""
    hw, hh = target.size_m / 2 + margin_m, target.face_height_m / 2 + margin_m
    return target.east_m - hw, target.height_m - hh, target.east_m + hw, target.height_m + hh


def image_size_m(config: SceneConfig, kind: str) -> tuple[float, float] | None:
    """(width, height) of a kind drawn as a picture on a panel; None for a built-in model."""
    kinds = config.vocabulary.kinds
    face = kinds[kind].face if kind in kinds else None
    return face.size_m if face is not None and face.image is not None else None


def is_image_kind(config: SceneConfig, kind: str) -> bool:
    return image_size_m(config, kind) is not None


def target_standoff_m(target: TargetParams) -> float:
    """How far the target's face stands off the wall."""
    standoffs = {"gauge": GAUGE_STANDOFF_M, "valve": VALVE_STANDOFF_M, "switchbox": SWITCHBOX_DEPTH_M}
    return standoffs.get(target.kind, IMAGE_PANEL_STANDOFF_M)


def rects_overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> bool:
    """Whether two (x0, y0, x1, y1) rectangles share interior points."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def mounts_for(
    target: TargetParams, config: SceneConfig, pipe_length_m: float | None = None
) -> tuple[WallItem, ...]:
    """What holds the target: a gauge's process pipe, a valve's pipe, a switch box's conduit.

    A pipe runs the wall's full width (`pipe_length_m` None: a single-target scene) or is a
    segment of that length centred on the target. They touch or pass behind the target by
    design, so they are laid out first and exempt from the keep-out rule (they never stand
    in front of the target's face).
    """
    w, h = config.wall.width_m, config.wall.height_m
    t = target
    east, length = (0.0, w) if pipe_length_m is None else (t.east_m, pipe_length_m)
    if t.kind == "gauge":
        up = t.height_m - t.face_height_m / 2 - t.mount_drop_m
        return (WallItem("pipe_h", east, up, length, 0.14, 0.13, MOUNT_PIPE_COLOUR, t.mount_variant),)
    if t.kind == "valve":
        return (WallItem("pipe_h", east, t.height_m, length, 0.16, 0.14, MOUNT_PIPE_COLOUR, t.mount_variant),)
    if t.kind != "switchbox":
        return ()  # a picture's panel is fastened to the wall itself
    top = t.height_m + t.face_height_m / 2
    return (WallItem("conduit_v", t.east_m, (top + h) / 2, 0.05, h - top, 0.05, "#b0b4b8"),)


class _TargetLayout:
    """Targets and their local mounts placed one by one: faces kept `keep_out_m` apart, no
    mount over another target's face (grown by the keep-out), mounts on the wall."""

    def __init__(self, config: SceneConfig) -> None:
        self.config = config
        self.keep = config.clutter.keep_out_m
        self.targets: list[TargetParams] = []
        self.mounts: list[tuple[int, WallItem]] = []  # (index of the target it holds, item)

    def _on_wall(self, rect: tuple[float, float, float, float]) -> bool:
        w, h = self.config.wall.width_m, self.config.wall.height_m
        return rect[0] >= -w / 2 and rect[2] <= w / 2 and rect[1] >= 0.0 and rect[3] <= h

    def add(self, target: TargetParams, mounts: tuple[WallItem, ...]) -> bool:
        face = target_footprint(target, self.keep)
        if not self._on_wall(target_footprint(target)):
            return False
        if any(rects_overlap(face, target_footprint(other)) for other in self.targets):
            return False
        if any(rects_overlap(face, m.footprint()) for _, m in self.mounts):
            return False
        for mount in mounts:
            if not self._on_wall(mount.footprint()):
                return False
            if any(rects_overlap(mount.footprint(), target_footprint(o, self.keep)) for o in self.targets):
                return False
            for _, other in self.mounts:
                crossing = LINEAR.get(mount.kind, "h") != LINEAR.get(other.kind, "h")
                if not crossing and rects_overlap(mount.footprint(0.03), other.footprint()):
                    return False
        index = len(self.targets)
        self.targets.append(target)
        self.mounts += [(index, m) for m in mounts]
        return True


def _kind_and_trim(
    config: SceneConfig, rng: np.random.Generator, placed: list[TargetParams], twin: bool
) -> tuple[str, str]:
    """The next other target's kind (the named one's for a twin, else an unused kind where one is
    left) and a trim colour whose name no target of that kind has yet."""
    cfg = config.target

    def free_colours(kind: str) -> tuple[str, ...]:
        if is_image_kind(config, kind):  # a picture has no trim to tell two apart: one of it at most
            return () if any(t.kind == kind for t in placed) else cfg.bezel_colours[:1]
        taken = {colour_name(t.bezel_colour) for t in placed if t.kind == kind}
        return tuple(c for c in cfg.bezel_colours if colour_name(c) not in taken)

    if twin:
        kind = placed[0].kind
    else:
        used = {t.kind for t in placed}
        fresh = tuple(k for k in cfg.other_kinds if k not in used)
        choices = tuple(k for k in (fresh or cfg.other_kinds) if free_colours(k))
        choices = choices or tuple(k for k in cfg.other_kinds if free_colours(k))
        if not choices:
            raise SceneLayoutError(f"no kind of {cfg.other_kinds} can be told apart from the targets placed")
        kind = str(pick(rng, choices))
    colours = free_colours(kind)
    if not colours:
        raise SceneLayoutError(f"a twin of {kind!r} cannot be told apart from it (a picture has no trim)")
    return kind, str(pick(rng, colours))


def _beside(
    config: SceneConfig, rng: np.random.Generator, named: TargetParams, t: TargetParams
) -> TargetParams:
    """`t` moved to a random spot beside the named target, its face on the wall."""
    side = 1.0 if rng.random() < 0.5 else -1.0
    east = named.east_m + side * uniform(rng, OTHER_EAST_M)
    up = named.height_m + float(rng.uniform(-OTHER_UP_M, OTHER_UP_M))
    half_w = config.wall.width_m / 2 - t.size_m / 2 - 0.1
    up = float(np.clip(up, t.face_height_m / 2 + 0.5, config.wall.height_m - t.face_height_m / 2 - 0.2))
    return replace(t, east_m=float(np.clip(east, -half_w, half_w)), height_m=up)


def sample_targets(
    config: SceneConfig, named: TargetParams, rng: np.random.Generator, seed: int
) -> tuple[tuple[TargetParams, ...], tuple[WallItem, ...]]:
    """(the other targets, every target's mounts, the named one's first), from their own stream `rng`.

    One target (`count` drawn 1): no others and the single-target scene's mounts.
    Raises `SceneLayoutError` when the others do not fit beside the named target.
    """
    lo, hi = config.target.count
    n = int(rng.integers(lo, hi + 1))
    if n == 1:
        return (), mounts_for(named, config)
    for _ in range(_LAYOUT_TRIES):
        layout = _TargetLayout(config)
        layout.add(named, mounts_for(named, config, uniform(rng, LOCAL_PIPE_M)))
        for i in range(n - 1):
            kind, trim = _kind_and_trim(config, rng, layout.targets, twin=config.target.twins and i == 0)
            drawn = sample_target(config, rng, kind, trim)
            for _ in range(_PLACE_TRIES):
                other = _beside(config, rng, named, drawn)
                if layout.add(other, mounts_for(other, config, uniform(rng, LOCAL_PIPE_M))):
                    break
            else:
                break  # no room for this one: lay the others out afresh
        if len(layout.targets) == n:
            return tuple(layout.targets[1:]), tuple(m for _, m in layout.mounts)
    raise SceneLayoutError(
        f"scene {seed}: {n} targets do not fit beside the named {named.kind} "
        f"(target.size_m {config.target.size_m}, clutter.keep_out_m {config.clutter.keep_out_m})"
    )
