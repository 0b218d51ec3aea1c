"""Where the goal image's target is in another image: multi-scale template matching (OpenCV).

A flown collection knows the target's box in one goal image (given by the operator, or found by the
detector for a known kind). Every other capture sees the same face from a pose a little to the side,
above, below, nearer or farther, with the same heading: the face moves and changes scale, but it does
not turn. So the goal crop (the box and a margin of the wall around it, which the face is fixed to) is
searched for at every scale in a range, normalised cross-correlation (`cv2.TM_CCOEFF_NORMED`) on grey
levels: coarse scale steps first, then fine ones around the best, and the peak refined to a fraction of
a pixel (a parabola through its neighbours, in position and in scale). The box maps with the crop.

A match under `min_score` is no match (`None`): the target is out of view, hidden, or another object.
The score is kept with the box: a flown collection checks the box against its pose geometry as well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

Box = tuple[float, float, float, float]
"""(u0, v0, u1, v1) in pixels, u right, v down."""


@dataclass(frozen=True)
class TrackedBox:
    """The target found in an image: its box, the box's centre, the match score and the scale to the goal."""

    bbox_px: Box
    centre_px: tuple[float, float]
    score: float
    scale: float


@dataclass(frozen=True)
class TrackerConfig:
    """Search range and acceptance of the template tracker."""

    scale_range: tuple[float, float] = (0.6, 1.7)
    """Scales of the face relative to the goal image (0.6: 1.7x as far as the goal, 1.7: 0.6x)."""
    coarse_step: float = 0.04
    fine_step: float = 0.01
    margin: float = 0.1
    """The wall around the box kept in the template, as a fraction of the box's size on each side (more
    wall matches better on flat faces, worse where the target stands off the wall: parallax)."""
    blur_px: float = 1.0
    """Gaussian blur (σ, pixels) of template and image: thin parts (a handwheel's spokes) and sensor noise
    then correlate over a pixel of misplacement instead of not at all."""
    min_score: float = 0.6
    min_template_px: int = 8

    def __post_init__(self) -> None:
        lo, hi = self.scale_range
        if not 0.1 <= lo < hi <= 10.0:
            raise ValueError(
                f"TrackerConfig.scale_range must be 0.1 <= lo < hi <= 10, got {self.scale_range}"
            )
        if not (0 < self.fine_step <= self.coarse_step):
            raise ValueError("TrackerConfig: need 0 < fine_step <= coarse_step")
        if not 0.0 <= self.margin <= 1.0 or not -1.0 < self.min_score < 1.0:
            raise ValueError("TrackerConfig: margin must be in [0, 1] and min_score in (-1, 1)")


class TemplateTracker:
    """Finds the goal image's box in other images (same heading; moved and scaled)."""

    def __init__(self, goal_image: np.ndarray, goal_box: Box, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        grey = _grey(goal_image, self.config.blur_px)
        height, width = grey.shape[:2]
        u0, v0, u1, v1 = (float(x) for x in goal_box)
        if not (0 <= u0 < u1 <= width and 0 <= v0 < v1 <= height):
            raise ValueError(f"goal box {goal_box} does not lie inside the {width}x{height} goal image")
        mu, mv = self.config.margin * (u1 - u0), self.config.margin * (v1 - v0)
        self._crop = (
            max(0, math.floor(u0 - mu)),
            max(0, math.floor(v0 - mv)),
            min(width, math.ceil(u1 + mu)),
            min(height, math.ceil(v1 + mv)),
        )
        x0, y0, x1, y1 = self._crop
        if min(x1 - x0, y1 - y0) < self.config.min_template_px:
            raise ValueError(
                f"goal box {goal_box} is too small to track (under {self.config.min_template_px} px)"
            )
        self._template = grey[y0:y1, x0:x1]
        self.goal_box: Box = (u0, v0, u1, v1)

    def track(
        self,
        image: np.ndarray,
        near_px: tuple[float, float] | None = None,
        radius_px: float | None = None,
        scale_hint: float | None = None,
    ) -> TrackedBox | None:
        """The goal box in `image` (None: no match of at least `min_score`).

        `near_px` + `radius_px`: search only for a box centre within `radius_px` of `near_px` (where the
        pose geometry puts the target): a wall of repeated bricks or a pipe holds places that match the
        goal crop almost as well as the target does, far from it. `scale_hint`: the scale the pose
        geometry expects; the search then spans `scale_hint` / 1.25 .. × 1.25 inside `scale_range`."""
        grey = _grey(image, self.config.blur_px)
        cfg = self.config
        lo, hi = cfg.scale_range
        if scale_hint is not None and math.isfinite(scale_hint) and scale_hint > 0:
            lo, hi = max(lo, scale_hint / 1.25), min(hi, scale_hint * 1.25)
            if lo >= hi:
                return None
        window = None if near_px is None or radius_px is None else (near_px, radius_px)
        matches = {
            float(s): self._match(grey, float(s), window) for s in np.arange(lo, hi + 1e-9, cfg.coarse_step)
        }
        best = max(matches, key=lambda s: matches[s].score)
        for s in np.arange(best - cfg.coarse_step, best + cfg.coarse_step + 1e-9, cfg.fine_step):
            if lo <= s <= hi and not any(math.isclose(s, k, abs_tol=1e-9) for k in matches):
                matches[float(s)] = self._match(grey, float(s), window)
        scale = max(matches, key=lambda s: matches[s].score)
        match = matches[scale]
        if not match.score >= cfg.min_score:
            return None
        refined = _refine_scale({s: m.score for s, m in matches.items()}, scale, cfg.fine_step)
        return self._box_at(match, refined / scale)

    def _match(
        self, grey: np.ndarray, scale: float, window: tuple[tuple[float, float], float] | None = None
    ) -> _Match:
        """The best place of the template at one scale (score -1 where it cannot fit), its centre within
        the window (centre, radius) when one is given."""
        th, tw = self._template.shape[:2]
        size = (max(1, round(tw * scale)), max(1, round(th * scale)))
        nothing = _Match(-1.0, (0.0, 0.0), (scale, scale))
        if size[0] > grey.shape[1] or size[1] > grey.shape[0] or min(size) < self.config.min_template_px:
            return nothing
        interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
        template = cv2.resize(self._template, size, interpolation=interpolation)
        ox = oy = 0
        if window is not None:  # the image part where a template centred within the window lies
            (u, v), radius = window
            ox = max(0, math.floor(u - radius - size[0] / 2.0))
            oy = max(0, math.floor(v - radius - size[1] / 2.0))
            x1 = min(grey.shape[1], math.ceil(u + radius + size[0] / 2.0))
            y1 = min(grey.shape[0], math.ceil(v + radius + size[1] / 2.0))
            if x1 - ox < size[0] + 2 or y1 - oy < size[1] + 2:
                return nothing
            grey = grey[oy:y1, ox:x1]
        scores = cv2.matchTemplate(grey, template, cv2.TM_CCOEFF_NORMED)
        _, peak, _, (px, py) = cv2.minMaxLoc(scores)
        dx = _parabola(scores[py, px - 1], peak, scores[py, px + 1]) if 0 < px < scores.shape[1] - 1 else 0.0
        dy = _parabola(scores[py - 1, px], peak, scores[py + 1, px]) if 0 < py < scores.shape[0] - 1 else 0.0
        # cv2.resize keeps the centre on the centre: the template's centre is where the crop's centre went.
        # Its real scale is the rounded size over the crop's, per axis.
        centre = (ox + px + dx + size[0] / 2.0, oy + py + dy + size[1] / 2.0)
        return _Match(float(peak), centre, (size[0] / tw, size[1] / th))

    def _box_at(self, match: _Match, refine: float) -> TrackedBox:
        """The goal box mapped through the crop's centre placed at the match, scaled (and refined)."""
        x0, y0, x1, y1 = self._crop
        u0, v0, u1, v1 = self.goal_box
        sx, sy = match.scale[0] * refine, match.scale[1] * refine
        crop_u, crop_v = (x0 + x1) / 2.0, (y0 + y1) / 2.0
        box = (
            match.centre[0] + (u0 - crop_u) * sx,
            match.centre[1] + (v0 - crop_v) * sy,
            match.centre[0] + (u1 - crop_u) * sx,
            match.centre[1] + (v1 - crop_v) * sy,
        )
        centre = ((box[0] + box[2]) / 2.0, (box[1] + box[3]) / 2.0)
        return TrackedBox(box, centre, match.score, (sx + sy) / 2.0)


@dataclass(frozen=True)
class _Match:
    score: float
    centre: tuple[float, float]
    """Where the template's centre lies in the image (pixels, sub-pixel)."""
    scale: tuple[float, float]


def _grey(image: np.ndarray, blur_px: float) -> np.ndarray:
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    return cv2.GaussianBlur(grey, (0, 0), blur_px) if blur_px > 0 else np.ascontiguousarray(grey)


def _parabola(left: float, middle: float, right: float) -> float:
    """The vertex offset (in [-0.5, 0.5]) of a parabola through three equally spaced samples."""
    denominator = left - 2.0 * middle + right
    if denominator >= 0.0:  # not a peak
        return 0.0
    return float(np.clip(0.5 * (left - right) / denominator, -0.5, 0.5))


def _refine_scale(scores: dict[float, float], scale: float, step: float) -> float:
    """The best scale refined between its fine neighbours (parabola through the three scores)."""
    near = sorted(scores)
    i = near.index(scale)
    if 0 < i < len(near) - 1 and math.isclose(near[i + 1] - near[i - 1], 2 * step, rel_tol=1e-3):
        return scale + step * _parabola(scores[near[i - 1]], scores[scale], scores[near[i + 1]])
    return scale
