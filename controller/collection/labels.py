"""A capture's label from two sources checked against each other: the image, and the pose geometry.

- Pose: the goal image saw the target at its offset, `depth_m` away along the camera's axis; that is a
  point in the vehicle's local frame, and the capture's pose (telemetry) projects it to an offset
  (`perception.camera_model`). As good as the pose estimate: PX4's drifts tenths of a metre at low
  altitude (SITL: ~10 px at 2 m), a rangefinder-less distance error scales the offset.
- Image (primary, the label itself): the goal image's box tracked in the capture
  (`perception.target_tracker`, template matching with scale), searched within `search_px` of where the
  pose geometry puts it (a brick wall or a pipe matches the template almost as well far from the target;
  the pose says where to look, the image says exactly where it is).

A pose estimate wanders (PX4 SITL's height estimate here: by up to 0.3 m, changing over tens of seconds
as the baro and GPS drift and the vehicle climbs and descends) while a tracker fails suddenly (another
place on the wall, a lost target). So the two are compared after the recent error is taken out: the bias is
the mean of the pose estimate's error across the camera's axis, in metres, over the last `bias_window`
accepted captures (zero at the goal, where both agree by construction), and a capture whose tracked offset
is more than `agree_px` from the pose's prediction with it is flagged (`disagree`), as one where the target
is not found (`not_found`) or found where the pose says it is out of view (`unexpected`). Flagged captures
stay on disk and out of training and scoring, and never move the bias, unless `reanchor_after` of them in
a row show the same error in metres from different poses: that is the estimate having moved (a wrong
match does not look the same from elsewhere), and it becomes the bias. The raw pose-derived offset is
recorded too (`dronectl dataset check` scores it alone against a simulator's truth). The ε rule
(`drone_inspect_core.centring`) makes the label from the offset later, at any ε.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.collection.goal import GoalRecord
from perception.camera_model import CameraModel, PoseNed
from perception.target_tracker import TemplateTracker, TrackerConfig

log = logging.getLogger(__name__)

MIN_SCORE = 0.5
"""The match score a label accepts: lower than the tracker's own default (0.6), because a label has a second
guard, the pose check, and a see-through target (a valve's handwheel) scores 0.5-0.6 from oblique views
while landing within 2 px of the truth."""


@dataclass(frozen=True)
class Label:
    """The label of one capture: where the target is (the image's, or the pose's for an empty view)."""

    offset_px: tuple[float, float]
    bbox_px: tuple[float, float, float, float] | None
    in_view: bool
    fully_in_view: bool
    flagged: bool
    reason: str | None
    image_offset_px: tuple[float, float] | None
    pose_offset_px: tuple[float, float] | None
    disagreement_px: float | None
    match_score: float | None
    scale: float | None
    pose_bias_px: tuple[float, float] = (0.0, 0.0)

    def record(self, tolerance_px: float, depth_m: float, distance_source: str) -> dict[str, Any]:
        """The manifest row's `label` field."""

        def pair(value: tuple[float, float] | None) -> list[float] | None:
            return None if value is None else [round(value[0], 3), round(value[1], 3)]

        return {
            "source": "image" if self.image_offset_px is not None else "pose",
            "flagged": self.flagged,
            "reason": self.reason,
            "image_offset_px": pair(self.image_offset_px),
            "pose_offset_px": pair(self.pose_offset_px),
            "pose_bias_px": pair(self.pose_bias_px),
            "disagreement_px": None if self.disagreement_px is None else round(self.disagreement_px, 3),
            "tolerance_px": round(tolerance_px, 3),
            "match_score": None if self.match_score is None else round(self.match_score, 4),
            "scale": None if self.scale is None else round(self.scale, 4),
            "goal_depth_m": round(depth_m, 4),
            "distance_source": distance_source,
        }


class LabelMaker:
    """Labels captures relative to one goal (its image, box, pose and distance)."""

    def __init__(
        self,
        camera: CameraModel,
        goal: GoalRecord,
        agree_px: float,
        tracker: TrackerConfig | None = None,
        search_factor: float = 1.6,
        bias_window: int = 2,
        reanchor_after: int = 3,
        unexpected_score: float = 0.8,
    ) -> None:
        if goal.image is None:
            raise ValueError("LabelMaker needs the goal image")
        self.camera, self.goal, self.agree_px = camera, goal, agree_px
        self.search_px = search_factor * agree_px
        self.tracker = TemplateTracker(goal.image, goal.box_px, tracker or TrackerConfig(min_score=MIN_SCORE))
        self._target = camera.point_ned(goal.pose, goal.offset_px, goal.depth_m)
        self.bias_window, self.reanchor_after = bias_window, reanchor_after
        self.unexpected_score = unexpected_score
        self._accepted: list[tuple[float, float]] = []
        self._disagreeing: list[tuple[float, float]] = []
        self.reanchored = 0

    @property
    def bias_m(self) -> tuple[float, float]:
        """The pose estimate's recent error across the camera's axis (right, down; metres): the mean of
        (image − pose) over the last `bias_window` accepted captures, turned into metres at their depth."""
        if not self._accepted:
            return 0.0, 0.0
        recent = np.array(self._accepted[-self.bias_window :])
        return float(recent[:, 0].mean()), float(recent[:, 1].mean())

    def _residual_m(
        self, image_px: tuple[float, float], pose_px: tuple[float, float], depth_m: float
    ) -> tuple[float, float]:
        return (image_px[0] - pose_px[0]) * depth_m / self.camera.fx, (
            image_px[1] - pose_px[1]
        ) * depth_m / self.camera.fy

    def observe(self, image_offset_px: tuple[float, float], pose: PoseNed) -> None:
        """The target seen at `image_offset_px` from `pose` with its pose agreed (a capture, or the goal
        flown to again on `--resume`): the pose estimate's error there."""
        du, dv, depth = self.pose_offset(pose)
        self._accepted.append(self._residual_m(image_offset_px, (du, dv), depth))
        self._disagreeing.clear()

    def _reanchor(self, residual_m: tuple[float, float], depth_m: float) -> None:
        """A pose estimate that has moved for good (a wrong match would not give the same error in metres
        at different poses): after `reanchor_after` disagreeing captures whose errors agree with each other,
        they become the bias. Those captures stay flagged; the ones after are compared afresh."""
        self._disagreeing.append(residual_m)
        recent = np.array(self._disagreeing[-self.reanchor_after :])
        if len(recent) < self.reanchor_after:
            return
        spread_px = (
            float(np.max(np.linalg.norm(recent - recent.mean(axis=0), axis=1))) * self.camera.fx / depth_m
        )
        if spread_px <= self.agree_px / 2.0:
            log.warning(
                "the pose estimate moved by %s m and stays there: comparing against that now",
                recent.mean(axis=0).round(2),
            )
            self._accepted = [tuple(r) for r in recent.tolist()]  # type: ignore[misc]
            self._disagreeing.clear()
            self.reanchored += 1

    def pose_offset(self, pose: PoseNed) -> tuple[float, float, float]:
        """(du, dv, depth) where the pose geometry puts the target seen from `pose`."""
        return self.camera.project_ned(pose, self._target)

    def label(self, image: np.ndarray, pose: PoseNed) -> Label:
        du, dv, depth = self.pose_offset(pose)
        width, height = self.camera.width, self.camera.height
        scale_hint = self.goal.depth_m / depth if depth > 0 else math.nan
        expected_in_view = depth > 0 and abs(du) < width / 2.0 and abs(dv) < height / 2.0
        pose_offset = (du, dv) if depth > 0 and math.isfinite(du) and math.isfinite(dv) else None
        if not expected_in_view:
            # An empty view: the label is the pose's (out of view), checked by the image showing nothing that
            # matches the goal's face well (`unexpected_score`: a round sign half matches a gauge) at about
            # the goal's scale (the wall is about as far) anywhere.
            found = self.tracker.track(image, scale_hint=1.0)
            if found is not None and found.score >= self.unexpected_score:
                return self._flagged("unexpected", pose_offset, found)
            offset = pose_offset if pose_offset is not None else (0.0, 0.0)  # out of view: never trained on
            return Label(offset, None, False, False, False, None, None, pose_offset, None, None, None)
        bias_m = self.bias_m
        bias = (bias_m[0] * self.camera.fx / depth, bias_m[1] * self.camera.fy / depth)
        near = (du + bias[0] + width / 2.0, dv + bias[1] + height / 2.0)
        found = self.tracker.track(image, near, self.search_px, scale_hint)
        if found is None:
            return self._flagged("not_found", pose_offset, None, bias)
        image_offset = (found.centre_px[0] - width / 2.0, found.centre_px[1] - height / 2.0)
        disagreement = math.hypot(image_offset[0] - du - bias[0], image_offset[1] - dv - bias[1])
        u0, v0, u1, v1 = found.bbox_px
        fully = u0 >= 0 and v0 >= 0 and u1 <= width and v1 <= height
        flagged = disagreement > self.agree_px
        if flagged:
            self._reanchor(self._residual_m(image_offset, (du, dv), depth), depth)
        else:
            self.observe(image_offset, pose)
        return Label(
            offset_px=image_offset,
            bbox_px=found.bbox_px,
            in_view=abs(image_offset[0]) < width / 2.0 and abs(image_offset[1]) < height / 2.0,
            fully_in_view=fully,
            flagged=flagged,
            reason="disagree" if flagged else None,
            image_offset_px=image_offset,
            pose_offset_px=(du, dv),
            disagreement_px=disagreement,
            match_score=found.score,
            scale=found.scale,
            pose_bias_px=bias,
        )

    def _flagged(
        self,
        reason: str,
        pose_offset: tuple[float, float] | None,
        found: Any,
        bias: tuple[float, float] = (0.0, 0.0),
    ) -> Label:
        width, height = self.camera.width, self.camera.height
        image_offset = (
            None if found is None else (found.centre_px[0] - width / 2.0, found.centre_px[1] - height / 2.0)
        )
        offset = image_offset or pose_offset or (0.0, 0.0)
        return Label(
            offset_px=offset,
            bbox_px=None if found is None else found.bbox_px,
            in_view=found is not None,
            fully_in_view=False,
            flagged=True,
            reason=reason,
            image_offset_px=image_offset,
            pose_offset_px=pose_offset,
            disagreement_px=None,
            match_score=None if found is None else found.score,
            scale=None if found is None else found.scale,
            pose_bias_px=bias,
        )
