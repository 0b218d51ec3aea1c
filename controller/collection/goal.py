"""The goal of a flown collection: the pose that centres the target, and what the goal image showed there.

`goal.json` (beside the dataset, and reusable with `collect --goal FILE`) holds the goal pose (local NED
+ yaw, from telemetry), the target's box in the goal image and its offset from the image centre, the
target's distance along the camera's axis and where that came from (given, or the forward
rangefinder), the camera model, and the goal image's file name (`goal.png` beside it). Labels are
made relative to it: the target's box is tracked from the goal image's box, and the pose geometry puts
the target where the goal image saw it.
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


class GoalFileError(ValueError):
    """A goal file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class GoalRecord:
    """The goal pose and what was seen from it."""

    pose: PoseNed
    box_px: tuple[float, float, float, float]
    """The target's box in the goal image (u0, v0, u1, v1)."""
    depth_m: float
    distance_source: str
    """"given" (--distance-m) or "rangefinder" (the forward rangefinder at the goal pose)."""
    box_source: str
    """"given" (--goal-box) or "detector"."""
    kind: str
    image_size: tuple[int, int]
    image: np.ndarray | None = None
    """The goal image (RGB), the tracker's template; None until read."""

    @property
    def offset_px(self) -> tuple[float, float]:
        u0, v0, u1, v1 = self.box_px
        width, height = self.image_size
        return (u0 + u1) / 2.0 - width / 2.0, (v0 + v1) / 2.0 - height / 2.0

    def geometry(self) -> GoalGeometry:
        return GoalGeometry(self.pose, self.offset_px, self.box_px, self.depth_m)

    def as_dict(self, camera: CameraModel) -> dict[str, Any]:
        return {
            "format": GOAL_FORMAT,
            "pose_ned": self.pose.as_dict(),
            "box_px": [round(v, 3) for v in self.box_px],
            "offset_px": [round(v, 3) for v in self.offset_px],
            "depth_m": round(self.depth_m, 4),
            "distance_source": self.distance_source,
            "box_source": self.box_source,
            "kind": self.kind,
            "image_size": list(self.image_size),
            "image": GOAL_IMAGE,
            "camera": camera.as_dict(),
        }


def save_goal(goal: GoalRecord, camera: CameraModel, folder: Path) -> Path:
    """Write `goal.png` and `goal.json` into `folder` (atomically); returns the JSON's path."""
    assert goal.image is not None
    ok, png = cv2.imencode(".png", cv2.cvtColor(goal.image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError(f"{folder / GOAL_IMAGE}: the goal image could not be encoded")
    write_atomic(folder / GOAL_IMAGE, png.tobytes())
    write_json_atomic(folder / GOAL_JSON, goal.as_dict(camera))
    return folder / GOAL_JSON


def load_goal(path: str | Path) -> GoalRecord:
    """Read a goal file and its image; `GoalFileError` names the file and the field at fault."""
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
        box = tuple(float(v) for v in data["box_px"])
        depth = float(data["depth_m"])
        size = (int(data["image_size"][0]), int(data["image_size"][1]))
        goal = GoalRecord(
            pose,
            box,
            depth,
            str(data["distance_source"]),
            str(data["box_source"]),
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
