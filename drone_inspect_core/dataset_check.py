"""`dronectl dataset check`: validate any dataset folder and count what it holds.

Every row is read through `dataset.load_manifest` (the format's one reader, flagged rows
included), every image is decoded and its size compared with `dataset.json`'s camera. The
counts are per split, sector and kind, and, for a flown dataset, how many captures were flagged
(their two label sources disagreed). A collection flown in a simulator also recorded the
simulator's truth per image (`truth`); the check then says how many labels agree with the truth's
labels at the dataset's ε, per source: the label itself (the image-tracked offset) and the
pose-derived offset, over the images kept for training (not flagged).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from drone_inspect_core.centring import axis_signs, default_epsilon_px
from drone_inspect_core.dataset import DatasetError, dataset_source, is_flagged, load_manifest
from drone_inspect_core.stats import Rate

log = logging.getLogger(__name__)

TRAINING_SPLITS = ("goal", "train")


@dataclass
class Agreement:
    """Of `n` images, how many have the same label (ε rule) from one source as from the truth, and how far
    the source's offset lies from the truth's (pixels)."""

    agree: int = 0
    n: int = 0
    disagreeing: list[str] = field(default_factory=list)
    errors_px: list[float] = field(default_factory=list)

    def add(self, row_id: str, same: bool, error_px: float) -> None:
        self.n += 1
        self.agree += int(same)
        self.errors_px.append(error_px)
        if not same:
            self.disagreeing.append(row_id)

    def error_quantiles(self) -> dict[str, float] | None:
        """Median, 95th percentile and largest distance from the truth's offset, pixels."""
        if not self.errors_px:
            return None
        values = np.array([e for e in self.errors_px if math.isfinite(e)])
        if not len(values):
            return None
        return {
            "median_px": round(float(np.median(values)), 3),
            "p95_px": round(float(np.percentile(values, 95)), 3),
            "max_px": round(float(values.max()), 3),
        }

    def as_dict(self) -> dict[str, Any]:
        return {**Rate(self.agree, self.n).as_dict(), "offset_error": self.error_quantiles(),
                "disagreeing": self.disagreeing[:50]}  # fmt: skip


@dataclass
class DatasetCheck:
    """What `check_dataset` found: counts, problems (none for a valid dataset), and the truth agreement."""

    root: Path
    source: str
    complete: bool
    epsilon_px: float
    rows: int
    by_split: dict[str, int]
    by_sector: dict[str, int]
    by_kind: dict[str, int]
    flagged: int
    flagged_by_reason: dict[str, int]
    problems: list[str]
    truth_rows: int = 0
    """Rows that carry the simulator's truth (a collection flown in a simulator)."""
    image_labels: Agreement | None = None
    pose_labels: Agreement | None = None
    flights: int | None = None

    @property
    def ok(self) -> bool:
        return not self.problems

    def as_dict(self) -> dict[str, Any]:
        return {
            "dataset": str(self.root),
            "source": self.source,
            "complete": self.complete,
            "epsilon_px": self.epsilon_px,
            "rows": self.rows,
            "by_split": self.by_split,
            "by_sector": self.by_sector,
            "by_kind": self.by_kind,
            "flagged": self.flagged,
            "flagged_fraction": self.flagged / self.rows if self.rows else None,
            "flagged_by_reason": self.flagged_by_reason,
            "flights": self.flights,
            "truth_rows": self.truth_rows,
            "labels_agree_with_truth": {
                "image": None if self.image_labels is None else self.image_labels.as_dict(),
                "pose": None if self.pose_labels is None else self.pose_labels.as_dict(),
            },
            "problems": self.problems,
            "ok": self.ok,
        }


def _label_of(offset: Any, in_view: bool, epsilon_px: float) -> tuple[int, int] | None:
    """The ε rule's label of an offset, None when the target is not in view."""
    if not in_view or offset is None:
        return None
    return axis_signs(float(offset[0]), float(offset[1]), epsilon_px)


def _truth_agreement(rows: list[dict[str, Any]], epsilon_px: float) -> tuple[Agreement, Agreement]:
    """Image-derived and pose-derived labels against the truth's, over the rows kept for training."""
    image, pose = Agreement(), Agreement()
    for row in rows:
        truth = row.get("truth")
        if not isinstance(truth, dict) or is_flagged(row) or row["split"] not in TRAINING_SPLITS:
            continue
        wanted = _label_of(truth.get("offset_px"), bool(truth.get("in_view")), epsilon_px)
        image.add(
            row["id"],
            _label_of(row["offset_px"], row["in_view"], epsilon_px) == wanted,
            _distance(row["offset_px"], truth.get("offset_px")),
        )
        pose_offset = row["label"].get("pose_offset_px")
        if pose_offset is not None:
            pose.add(
                row["id"],
                _label_of(pose_offset, row["in_view"], epsilon_px) == wanted,
                _distance(pose_offset, truth.get("offset_px")),
            )
    return image, pose


def _distance(offset: Any, truth: Any) -> float:
    if offset is None or truth is None or None in truth:
        return math.nan
    return math.dist((float(offset[0]), float(offset[1])), (float(truth[0]), float(truth[1])))


def _image_problems(root: Path, rows: list[dict[str, Any]], width: int, height: int) -> list[str]:
    problems = []
    for row in tqdm(rows, desc=f"check {root.name}", unit="img", leave=False):
        image = cv2.imread(str(root / row["image"]), cv2.IMREAD_UNCHANGED)
        if image is None:
            problems.append(f"{root / row['image']}: not a readable image (row {row['id']})")
        elif image.shape[:2] != (height, width):
            problems.append(
                f"{root / row['image']}: {image.shape[1]}x{image.shape[0]} px, dataset.json's camera says "
                f"{width}x{height} (row {row['id']})"
            )
    return problems


def check_dataset(directory: str | Path, decode_images: bool = True) -> DatasetCheck:
    """Validate `directory` and count it; raises `DatasetError` (naming the file and line) when the
    manifest cannot be read at all, else lists the problems found (unreadable or mis-sized images,
    duplicate ids or image files)."""
    root = Path(directory)
    rows, meta = load_manifest(root, include_flagged=True)
    try:
        width, height = int(meta["camera"]["width"]), int(meta["camera"]["height"])
    except (KeyError, TypeError, ValueError):
        raise DatasetError(f"{root / 'dataset.json'}: field 'camera' needs width and height") from None
    epsilon_px = float(meta.get("epsilon_px") or default_epsilon_px(width))
    problems = []
    for name in ("id", "image"):
        repeated = [value for value, n in Counter(row[name] for row in rows).items() if n > 1]
        if repeated:
            problems.append(f"{len(repeated)} {name}s appear more than once, e.g. {repeated[0]!r}")
    if decode_images:
        problems += _image_problems(root, rows, width, height)
    flagged = [row for row in rows if is_flagged(row)]
    check = DatasetCheck(
        root=root,
        source=dataset_source(meta),
        complete=bool(meta.get("complete", True)),
        epsilon_px=epsilon_px,
        rows=len(rows),
        by_split=dict(Counter(row["split"] for row in rows)),
        by_sector=dict(Counter(row["sector"] for row in rows)),
        by_kind=dict(Counter(row["target_kind"] for row in rows)),
        flagged=len(flagged),
        flagged_by_reason=dict(Counter(str(row["label"].get("reason")) for row in flagged)),
        problems=problems,
        flights=len({row["flight"] for row in rows if "flight" in row}) or None,
    )
    truth_rows = [row for row in rows if isinstance(row.get("truth"), dict)]
    if truth_rows:
        check.truth_rows = len(truth_rows)
        check.image_labels, check.pose_labels = _truth_agreement(truth_rows, epsilon_px)
    return check
