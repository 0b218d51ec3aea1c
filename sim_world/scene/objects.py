"""The scene's objects as PyBullet bodies: wall, floor, the target of each kind, mounts, clutter.

Geometry only: what to build comes from `scene_sampling` (already drawn), textures
from `textures*.py` through the asset cache. Positions are ENU; the wall is the plane
y = north facing −y, so "standing off the wall by s" means y = north − s. Triangle
counts are kept small (TinyRenderer's cost grows with them): a cylinder is one
primitive, faces are 2-triangle quads or 32-triangle discs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drone_inspect_core.vocabulary import Vocabulary
from sim_world.scene.assets import AssetCache
from sim_world.scene.bodies import ALONG_X, ALONG_Y, ALONG_Z, BodyBuilder, Part, along_xz, shaded
from sim_world.scene.config import hex_to_rgb
from sim_world.scene.sampling import (
    GAUGE_STANDOFF_M,
    SWITCHBOX_DEPTH_M,
    VALVE_STANDOFF_M,
    SceneParams,
    TargetParams,
    WallItem,
)
from sim_world.scene.sampling_targets import IMAGE_PANEL_STANDOFF_M
from sim_world.scene.textures import FLOOR_TILE_M, WALL_TILE_M, floor_texture, wall_texture
from sim_world.scene.textures_targets import (
    gauge_dial,
    instrument_dial,
    picture_texture,
    round_sign,
    switchbox_panel,
    wall_sign,
)

PICTURE_WIDTH_PX = 256
"""A picture face's texture width (its height follows the panel's aspect)."""
OUTLINE_POINTS = 24
"""Points on a round target's outline (a rectangle gets 5 per side)."""
FLOOR_SIZE_M = 30.0
_FACE_GAP_M = 0.0015
"""A textured face floats this far in front of the part behind it (no depth fighting)."""
_SHORT_PIPE_M = 2.0
"""Pipes shorter than this (local mounts) keep their flanges and clamps on them; longer ones span the wall."""


@dataclass(frozen=True)
class BuiltTarget:
    body_id: int
    centre_enu_m: np.ndarray
    """(3,) centre of the front face."""
    outline_enu_m: np.ndarray
    """(N, 3) ordered loop around the front face."""
    mount_body_ids: tuple[int, ...]


def build_wall(
    builder: BodyBuilder, assets: AssetCache, params: SceneParams, north: float, width: float, height: float
) -> int:
    tile = WALL_TILE_M[params.wall_texture]
    key = ("wall", params.wall_texture, params.wall_colour, params.wall_variant)
    texture = assets.png(
        key, lambda: wall_texture(params.wall_texture, hex_to_rgb(params.wall_colour), params.wall_variant)
    )
    face = Part(
        "mesh",
        (width, 1.0, height),
        (0.0, 0.0, 0.0),
        mesh=assets.quad("front", width / tile, height / tile),
        texture=texture,
    )
    return builder.body([face], (0.0, north, height / 2), (width / 2, 0.1, height / 2), (0.0, 0.1, 0.0))


def build_floor(
    builder: BodyBuilder, assets: AssetCache, params: SceneParams, north: float
) -> tuple[int, int]:
    """The visible floor (a tiled quad) and its collision plane at z = 0: (visual id, collider id)."""
    tile = FLOOR_TILE_M[params.floor_texture]
    key = ("floor", params.floor_texture, params.floor_colour, params.floor_variant)
    texture = assets.png(
        key,
        lambda: floor_texture(params.floor_texture, hex_to_rgb(params.floor_colour), params.floor_variant),
    )
    size = FLOOR_SIZE_M
    mesh = assets.quad("up", size / tile, size / tile, cells=4)
    collider = builder.plane_collider()
    visual = builder.body(
        [Part("mesh", (size, size, 1.0), (0.0, 0.0, 0.0), mesh=mesh, texture=texture)],
        (0.0, north - size / 2 + 2.0, 0.0),
    )
    return visual, collider


def circle_outline(centre: np.ndarray, radius: float, n: int = OUTLINE_POINTS) -> np.ndarray:
    """An ordered loop of `n` points on a circle in the wall-parallel plane through `centre`."""
    angles = 2.0 * np.pi * np.arange(n) / n
    return centre + radius * np.stack([np.cos(angles), np.zeros(n), np.sin(angles)], axis=1)


def rectangle_outline(centre: np.ndarray, width: float, height: float, per_side: int = 5) -> np.ndarray:
    """An ordered loop around a wall-parallel rectangle, `per_side` points per edge."""
    hw, hh = width / 2, height / 2
    corners = [(-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh)]
    points = []
    for (x0, z0), (x1, z1) in zip(corners, corners[1:] + corners[:1], strict=True):
        for k in range(per_side):
            t = k / per_side
            points.append((x0 + t * (x1 - x0), 0.0, z0 + t * (z1 - z0)))
    return centre + np.asarray(points)


def _gauge(builder: BodyBuilder, assets: AssetCache, t: TargetParams, north: float) -> BuiltTarget:
    r = t.size_m / 2
    face_y = north - GAUGE_STANDOFF_M
    key = ("gauge", t.dial_colour, t.bezel_colour, t.needle_fraction, t.gauge_scale, t.red_zone, t.red_needle)
    dial = assets.png(
        key,
        lambda: gauge_dial(
            hex_to_rgb(t.dial_colour),
            hex_to_rgb(t.bezel_colour),
            t.needle_fraction,
            t.gauge_scale,
            t.red_zone,
            t.red_needle,
        ),
    )
    # The target body is the face and its bezel ring; the case behind it is part of the
    # mount, so the target's mask is what its outline bounds, even from oblique views.
    bezel_len, case_len = 0.016, 0.06
    parts = [
        Part("mesh", (r, 1.0, r), (0.0, 0.0, 0.0), mesh=assets.disc(), texture=dial),
        Part("cylinder", (r, bezel_len), (0.0, _FACE_GAP_M + bezel_len / 2, 0.0), t.bezel_colour, ALONG_Y),
    ]
    centre = np.array([t.east_m, face_y, t.height_m])
    body = builder.body(parts, tuple(centre), (r, bezel_len / 2, r), (0.0, bezel_len / 2, 0.0))
    # The case, and the stem from its bottom down into the process pipe (scene_sampling.mounts_for).
    pipe_z = t.height_m - r - t.mount_drop_m
    stem_top, case_y = t.height_m - 0.85 * r, face_y + bezel_len + case_len / 2
    stem_len = stem_top - pipe_z
    mount_parts = [
        Part("cylinder", (0.88 * r, case_len), (0.0, 0.0, 0.0), shaded(t.bezel_colour, 0.6), ALONG_Y),
        Part(
            "cylinder", (0.011, stem_len), (0.0, 0.0, pipe_z + stem_len / 2 - t.height_m), "#b08d57"
        ),  # brass
        Part("box", (0.02, 0.02, 0.012), (0.0, 0.0, stem_top - 0.05 - t.height_m), "#9c9c9c"),  # hex socket
    ]
    mount = builder.body(mount_parts, (t.east_m, case_y, t.height_m), (0.88 * r, case_len / 2, 0.88 * r))
    return BuiltTarget(body, centre, circle_outline(centre, r), (mount,))


def _valve(builder: BodyBuilder, t: TargetParams, north: float) -> BuiltTarget:
    outer = t.size_m / 2
    tube = max(0.01, 0.07 * outer)
    rim_r = outer - tube
    segments = 14
    seg_len = 2 * rim_r * math.sin(math.pi / segments) + tube  # overlapping: no gaps at the joints
    parts: list[Part] = [
        Part("cylinder", (0.16 * outer, 2.6 * tube), (0.0, tube, 0.0), "#3a3a3a", ALONG_Y)
    ]  # hub
    for k in range(segments):
        mid = 2 * math.pi * (k + 0.5) / segments
        pos = (rim_r * math.cos(mid), tube, rim_r * math.sin(mid))
        parts.append(Part("cylinder", (tube, seg_len), pos, t.bezel_colour, along_xz(mid + math.pi / 2)))
    spoke_len = rim_r - 0.1 * outer
    for k in range(t.spokes):
        angle = 2 * math.pi * k / t.spokes + math.pi / 2
        mid_r = 0.1 * outer + spoke_len / 2
        pos = (mid_r * math.cos(angle), tube, mid_r * math.sin(angle))
        parts.append(Part("cylinder", (0.55 * tube, spoke_len), pos, t.bezel_colour, along_xz(angle)))
    face_y = north - VALVE_STANDOFF_M
    centre = np.array([t.east_m, face_y, t.height_m])
    body = builder.body(parts, tuple(centre), (outer, tube, outer), (0.0, tube, 0.0))
    # Stem (from the back of the hub), bonnet and valve body, back to the pipe behind it
    # (scene_sampling.mounts_for); the valve body ends 1 cm off the wall.
    hub_back = 2.3 * tube
    bonnet, valve_body = 0.06, 0.09
    stem_len = VALVE_STANDOFF_M - hub_back - bonnet - valve_body - 0.01
    mount_parts = [
        Part("cylinder", (0.014, stem_len), (0.0, 0.0, 0.0), "#9c9c9c", ALONG_Y),
        Part("box", (0.045, bonnet / 2, 0.045), (0.0, stem_len / 2 + bonnet / 2, 0.0), "#50555a"),
        Part(
            "cylinder",
            (0.085, valve_body),
            (0.0, stem_len / 2 + bonnet + valve_body / 2, 0.0),
            "#50555a",
            ALONG_Y,
        ),
    ]
    mount = builder.body(mount_parts, (t.east_m, face_y + hub_back + stem_len / 2, t.height_m))
    return BuiltTarget(body, centre, circle_outline(centre, outer), (mount,))


def _switchbox(builder: BodyBuilder, assets: AssetCache, t: TargetParams, north: float) -> BuiltTarget:
    w, h, d = t.size_m, t.face_height_m, SWITCHBOX_DEPTH_M
    height_px = round(256 * h / w)
    key = (
        "switchbox",
        t.dial_colour,
        t.bezel_colour,
        t.label_index,
        t.label_number,
        t.switches,
        t.lights,
        height_px,
    )
    panel = assets.png(
        key,
        lambda: switchbox_panel(
            hex_to_rgb(t.dial_colour),
            hex_to_rgb(t.bezel_colour),
            t.label_index,
            t.label_number,
            t.switches,
            t.lights,
            height_px=height_px,
        ),
    )
    # The target body is the door; the enclosure behind it, a little smaller, is the mount
    # (so the target's mask is what its outline bounds, even from oblique views).
    door = 0.015
    parts = [
        Part("mesh", (w, 1.0, h), (0.0, 0.0, 0.0), mesh=assets.quad("front"), texture=panel),
        Part(
            "box", (w / 2, door / 2, h / 2), (0.0, _FACE_GAP_M + door / 2, 0.0), shaded(t.dial_colour, 0.85)
        ),
    ]
    centre = np.array([t.east_m, north - d - _FACE_GAP_M, t.height_m])
    body = builder.body(parts, tuple(centre), (w / 2, door / 2, h / 2), (0.0, door / 2, 0.0))
    inset, depth = 0.012, d - door
    enclosure = Part(
        "box", (w / 2 - inset, depth / 2, h / 2 - inset), (0.0, 0.0, 0.0), shaded(t.dial_colour, 0.7)
    )
    box_y = centre[1] + _FACE_GAP_M + door + depth / 2
    mount = builder.body(
        [enclosure], (t.east_m, box_y, t.height_m), (w / 2 - inset, depth / 2, h / 2 - inset)
    )
    return BuiltTarget(body, centre, rectangle_outline(centre, w, h), (mount,))


def _picture(
    builder: BodyBuilder, assets: AssetCache, t: TargetParams, north: float, image: Path
) -> BuiltTarget:
    """A kind of the user's own: its picture on a thin panel fastened to the wall (`Face.image`)."""
    w, h = t.size_m, t.face_height_m
    height_px = max(8, round(PICTURE_WIDTH_PX * h / w))
    stat = image.stat()
    texture = assets.png(
        ("picture", str(image), stat.st_mtime_ns, stat.st_size, height_px),
        lambda: picture_texture(image, PICTURE_WIDTH_PX, height_px),
    )
    backing = 0.012
    parts = [
        Part("mesh", (w, 1.0, h), (0.0, 0.0, 0.0), mesh=assets.quad("front"), texture=texture),
        Part("box", (w / 2, backing / 2, h / 2), (0.0, _FACE_GAP_M + backing / 2, 0.0), "#3c3f42"),
    ]
    centre = np.array([t.east_m, north - IMAGE_PANEL_STANDOFF_M, t.height_m])
    body = builder.body(parts, tuple(centre), (w / 2, backing / 2, h / 2), (0.0, backing / 2, 0.0))
    return BuiltTarget(body, centre, rectangle_outline(centre, w, h), ())


def build_target(
    builder: BodyBuilder, assets: AssetCache, t: TargetParams, north: float, vocabulary: Vocabulary
) -> BuiltTarget:
    """The target's bodies: a built-in model, or the picture of a kind of the user's own."""
    face = vocabulary.kind(t.kind).face
    model = face.model or t.kind
    if face.image is not None:
        return _picture(builder, assets, t, north, face.image)
    if model == "gauge":
        return _gauge(builder, assets, t, north)
    if model == "valve":
        return _valve(builder, t, north)
    if model == "switchbox":
        return _switchbox(builder, assets, t, north)
    raise ValueError(f"target kind {t.kind!r} has neither a built-in model nor a picture")


def _pipe(builder: BodyBuilder, item: WallItem, north: float, horizontal: bool, conduit: bool) -> int:
    """A pipe or conduit across the wall, with flanges and clamps for pipes."""
    radius = (item.height_m if horizontal else item.width_m) / (2.0 if conduit else 2.8)
    length = item.width_m if horizontal else item.height_m
    axis = ALONG_X if horizontal else ALONG_Z
    parts = [Part("cylinder", (radius, length), (0.0, 0.0, 0.0), item.colour, axis)]
    if not conduit:
        rng = np.random.default_rng(item.variant)
        # Flanges within 2 m of the middle; on a short pipe (a local mount) within its length.
        reach = 1.0 if length >= _SHORT_PIPE_M else max(0.0, length / 2 - 0.1) / 2.0
        for offset in reach * rng.uniform(-2.0, 2.0, size=2):
            along = (float(offset), 0.0, 0.0) if horizontal else (0.0, 0.0, float(offset))
            parts.append(Part("cylinder", (1.4 * radius, 0.05), along, shaded(item.colour, 0.8), axis))
            to_wall = item.standoff_m - radius  # from the pipe's axis back to the wall
            step = 0.15 if length >= _SHORT_PIPE_M or offset < 0 else -0.15  # a clamp towards the middle
            shift = (step, 0.0, 0.0) if horizontal else (0.0, 0.0, step)
            clamp = (along[0] + shift[0], to_wall / 2, along[2] + shift[2])
            parts.append(Part("box", (0.02, to_wall / 2, 0.02), clamp, "#3c3f42"))
    y = north - item.standoff_m + radius
    return builder.body(parts, (item.east_m, y, item.up_m), (item.width_m / 2, radius, item.height_m / 2))


def build_item(builder: BodyBuilder, assets: AssetCache, item: WallItem, north: float) -> int:
    """One clutter item or distractor on the wall."""
    k = item.kind
    if k in ("pipe_h", "pipe_v", "conduit_h", "conduit_v"):
        return _pipe(builder, item, north, k.endswith("_h"), k.startswith("conduit"))
    centre = (item.east_m, north - item.standoff_m, item.up_m)
    hw, hh, d = item.width_m / 2, item.height_m / 2, item.standoff_m
    if k in ("junction_box", "box", "bracket"):
        box = Part("box", (hw, d / 2, hh), (0.0, d / 2, 0.0), item.colour)
        return builder.body([box], centre, (hw, d / 2, hh), (0.0, d / 2, 0.0))
    if k == "sign":
        texture = assets.png(("sign", item.variant), lambda: wall_sign(item.variant))
        face = Part(
            "mesh",
            (item.width_m, 1.0, item.height_m),
            (0.0, 0.0, 0.0),
            mesh=assets.quad("front"),
            texture=texture,
        )
        return builder.body([face], centre)
    if k == "dial":
        fraction = (item.variant % 100) / 100
        texture = assets.png(
            ("idial", item.colour, fraction), lambda: instrument_dial(hex_to_rgb(item.colour), fraction)
        )
        face = Part("mesh", (hw, 1.0, hw), (0.0, 0.0, 0.0), mesh=assets.disc(), texture=texture)
        case = Part("cylinder", (hw, d), (0.0, _FACE_GAP_M + d / 2, 0.0), "#a5a8ac", ALONG_Y)
        return builder.body([face, case], centre, (hw, d / 2, hw), (0.0, d / 2, 0.0))
    if k == "round_sign":
        texture = assets.png(("rsign", item.variant), lambda: round_sign(bool(item.variant)))
        return builder.body(
            [Part("mesh", (hw, 1.0, hw), (0.0, 0.0, 0.0), mesh=assets.disc(), texture=texture)], centre
        )
    raise ValueError(f"unknown wall item kind {k!r}")
