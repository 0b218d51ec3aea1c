"""Ground truth of where the inspection target sits in the camera image.

The truth comes from geometry, not from the rendered pixels: the target's centre
and the outline of its face are projected with the camera's pinhole model (which
the renderer matches to a fraction of a pixel, see `camera.py`). The bounding box
is that of the projected outline clipped to the image; the visible fraction is the
share of the outline's projected area inside the image. Given a render with a
segmentation mask, the truth also counts the target's pixels in it (`mask_px`),
which tells whether anything of the target is actually seen (occlusion included;
a handwheel's mask covers only its rim and spokes, so a pixel count is not a
fraction of the outline).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_world.rendering.camera import BodyPose, ForwardCamera, Render


@dataclass(frozen=True)
class TargetTruth:
    """The target in one image (pixels: u right, v down, origin top-left)."""

    centre_px: tuple[float, float]
    bbox_px: tuple[float, float, float, float] | None
    """(u0, v0, u1, v1) of the projected outline clipped to the image; None when none of it is in view."""
    in_view: bool
    """The centre is in front of the camera and inside the image."""
    fully_in_view: bool
    """Every outline point is in front of the camera and inside the image."""
    visible_fraction: float
    depth_m: float
    """Depth of the target centre along the optical axis."""
    image_size: tuple[int, int]
    """(width, height) of the image the truth refers to."""
    mask_px: int | None = None
    """Target pixels in the render's segmentation mask; None when no mask was given."""

    @property
    def offset_px(self) -> tuple[float, float]:
        """(du, dv) = centre − (W/2, H/2)."""
        w, h = self.image_size
        return self.centre_px[0] - w / 2.0, self.centre_px[1] - h / 2.0


def polygon_area(points: np.ndarray) -> float:
    """Unsigned area of a simple polygon (shoelace)."""
    if len(points) < 3:
        return 0.0
    x, y = points[:, 0], points[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def clip_polygon(points: np.ndarray, width: float, height: float) -> np.ndarray:
    """Sutherland–Hodgman clipping of a polygon to the rectangle [0, width] × [0, height]."""
    poly = [tuple(pt) for pt in points]
    # Each edge: (axis, limit, keep_if_greater)
    for axis, limit, keep_greater in ((0, 0.0, True), (0, width, False), (1, 0.0, True), (1, height, False)):
        if not poly:
            break
        out: list[tuple[float, float]] = []
        for i, cur in enumerate(poly):
            prev = poly[i - 1]
            cur_in = cur[axis] >= limit if keep_greater else cur[axis] <= limit
            prev_in = prev[axis] >= limit if keep_greater else prev[axis] <= limit
            if cur_in:
                if not prev_in:
                    out.append(_intersect(prev, cur, axis, limit))
                out.append(cur)
            elif prev_in:
                out.append(_intersect(prev, cur, axis, limit))
        poly = out
    return np.array(poly, dtype=float).reshape(-1, 2)


def _intersect(
    a: tuple[float, float], b: tuple[float, float], axis: int, limit: float
) -> tuple[float, float]:
    t = (limit - a[axis]) / (b[axis] - a[axis])
    return a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])


def target_truth(
    camera: ForwardCamera,
    state: BodyPose,
    centre_enu_m: np.ndarray,
    outline_enu_m: np.ndarray,
    target_body_id: int,
    render: Render | None = None,
) -> TargetTruth:
    """Project the target's centre and outline into the image of `camera` at `state`.

    With a `render` holding a segmentation mask, also count the target's pixels in it.
    """
    k = camera.intrinsics
    w, h = k.width, k.height
    uv, depth = camera.project(np.vstack([centre_enu_m[None, :], outline_enu_m]), state)
    centre, centre_depth = uv[0], float(depth[0])
    outline, outline_depth = uv[1:], depth[1:]
    near = camera.config.near_m
    in_front = outline_depth > near
    inside = (
        in_front & (outline[:, 0] >= 0) & (outline[:, 0] <= w) & (outline[:, 1] >= 0) & (outline[:, 1] <= h)
    )
    in_view = bool(centre_depth > near and 0.0 <= centre[0] < w and 0.0 <= centre[1] < h)
    fully_in_view = bool(inside.all())

    front = outline[in_front]
    clipped = clip_polygon(front, w, h) if len(front) >= 3 else np.zeros((0, 2))
    full_area = polygon_area(front)
    inside_area = polygon_area(clipped)
    bbox: tuple[float, float, float, float] | None = None
    if inside_area > 0.0:
        lo, hi = clipped.min(axis=0), clipped.max(axis=0)
        bbox = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    fraction = inside_area / full_area if full_area > 0.0 else 0.0
    mask_px = None
    if render is not None and render.seg is not None:
        mask_px = int(np.count_nonzero(render.seg == target_body_id))
    return TargetTruth(
        centre_px=(float(centre[0]), float(centre[1])),
        bbox_px=bbox,
        in_view=in_view,
        fully_in_view=fully_in_view,
        visible_fraction=float(min(1.0, max(0.0, fraction))),
        depth_m=centre_depth,
        image_size=(w, h),
        mask_px=mask_px,
    )
