"""The goal of a flown collection: the pose that centres the target, and what the goal image showed there.

`goal.json` (beside the dataset, and reusable with `collect --goal FILE`) holds the goal pose (local NED
+ yaw, from telemetry), the target's box in the goal image and its offset from the image centre, the
target's distance along the camera's axis and where that came from (given, or the forward
rangefinder), the camera model, and the goal image's file name (`goal.png` beside it). Labels are
made relative to it: the target's box is tracked from the goal image's box, and the pose geometry puts
the target where the goal image saw it.

A goal whose box nobody knows yet (a kind the detector does not know, and no `--goal-box`) is saved as a
candidate, `goal_candidate.json` + `goal_candidate.png` with no box: the operator reads the target's box
off that very image and flies from it, `--goal DIR/goal_candidate.json --goal-box x,y,w,h`, so the box
is exact in the goal image every label is tracked from.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from controller.collection.plan import GoalGeometry
from drone_inspect_core.files import write_atomic, write_json_atomic
from perception.camera_model import CameraModel, PoseNed

GOAL_JSON = "goal.json"
GOAL_IMAGE = "goal.png"
GOAL_FORMAT = "dronectl.goal/1"
CANDIDATE = "goal_candidate"
"""The stem of a goal saved without the target's box."""


class GoalFileError(ValueError):
    """A goal file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class GoalRecord:
    """The goal pose and what was seen from it."""

    pose: PoseNed
    box_px: tuple[float, float, float, float] | None
    """The target's box in the goal image (u0, v0, u1, v1); None in a goal candidate."""
    depth_m: float
    distance_source: str
    """"given" (--distance-m) or "rangefinder" (the forward rangefinder at the goal pose)."""
    box_source: str
    """"given" (--goal-box), "detector", or "none" (a candidate)."""
    kind: str
    image_size: tuple[int, int]
    image: np.ndarray | None = None
    """The goal image (RGB), the tracker's template; None until read."""

    @property
    def offset_px(self) -> tuple[float, float]:
        if self.box_px is None:
            raise GoalFileError("a goal candidate has no target box: give it with --goal-box x,y,w,h")
        u0, v0, u1, v1 = self.box_px
        width, height = self.image_size
        return (u0 + u1) / 2.0 - width / 2.0, (v0 + v1) / 2.0 - height / 2.0

    def geometry(self) -> GoalGeometry:
        assert self.box_px is not None
        return GoalGeometry(self.pose, self.offset_px, self.box_px, self.depth_m)

    def as_dict(self, camera: CameraModel, image: str = GOAL_IMAGE) -> dict[str, Any]:
        box = None if self.box_px is None else [round(v, 3) for v in self.box_px]
        return {
            "format": GOAL_FORMAT,
            "pose_ned": self.pose.as_dict(),
            "box_px": box,
            "offset_px": None if box is None else [round(v, 3) for v in self.offset_px],
            "depth_m": round(self.depth_m, 4),
            "distance_source": self.distance_source,
            "box_source": self.box_source,
            "kind": self.kind,
            "image_size": list(self.image_size),
            "image": image,
            "camera": camera.as_dict(),
        }


def save_goal(goal: GoalRecord, camera: CameraModel, folder: Path, stem: str = "goal") -> Path:
    """Write `<stem>.png` and `<stem>.json` into `folder` (atomically); returns the JSON's path."""
    assert goal.image is not None
    image = f"{stem}.png"
    ok, png = cv2.imencode(".png", cv2.cvtColor(goal.image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError(f"{folder / image}: the goal image could not be encoded")
    write_atomic(folder / image, png.tobytes())
    write_json_atomic(folder / f"{stem}.json", goal.as_dict(camera, image))
    return folder / f"{stem}.json"


def box_from_xywh(xywh: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """`--goal-box x,y,w,h` as (u0, v0, u1, v1)."""
    x, y, w, h = xywh
    return x, y, x + w, y + h


def load_goal(path: str | Path, goal_box: tuple[float, float, float, float] | None = None) -> GoalRecord:
    """Read a goal file and its image; `GoalFileError` names the file and the field at fault. `goal_box`
    (x, y, w, h, the operator's `--goal-box`) is the target's box in its image instead of the file's: a
    goal candidate (no box) needs one."""
    path = Path(path)
    if path.is_dir():
        path = path / GOAL_JSON
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise GoalFileError(f"{path}: no such goal file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GoalFileError(f"{path}: unreadable: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != GOAL_FORMAT:
        raise GoalFileError(f"{path}: not a goal file (expected 'format': {GOAL_FORMAT!r})")
    try:
        pose = PoseNed(**{k: float(v) for k, v in data["pose_ned"].items()})
        stored = data["box_px"]
        if goal_box is None and stored is None:
            raise GoalFileError(
                f"{path}: a goal candidate without the target's box: read the box off its image "
                f"({data.get('image')}) and give it with --goal-box x,y,w,h"
            )
        box = box_from_xywh(goal_box) if goal_box is not None else tuple(float(v) for v in stored)
        depth = float(data["depth_m"])
        size = (int(data["image_size"][0]), int(data["image_size"][1]))
        goal = GoalRecord(
            pose,
            box,
            depth,
            str(data["distance_source"]),
            "given" if goal_box is not None else str(data["box_source"]),
            str(data["kind"]),
            size,  # type: ignore[arg-type]
        )
        image_name = str(data["image"])
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise GoalFileError(f"{path}: field {exc} missing or malformed") from None
    if len(box) != 4 or not (math.isfinite(depth) and depth > 0):
        raise GoalFileError(f"{path}: field 'box_px' needs 4 numbers and 'depth_m' a distance > 0")
    bgr = cv2.imread(str(path.parent / image_name), cv2.IMREAD_COLOR)
    if bgr is None:
        raise GoalFileError(f"{path.parent / image_name}: the goal image is missing or unreadable")
    if (bgr.shape[1], bgr.shape[0]) != size:
        raise GoalFileError(
            f"{path.parent / image_name}: {bgr.shape[1]}x{bgr.shape[0]} px, goal.json says {size}"
        )
    return GoalRecord(pose, goal.box_px, depth, goal.distance_source, goal.box_source, goal.kind, size,
                      cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))  # fmt: skip
