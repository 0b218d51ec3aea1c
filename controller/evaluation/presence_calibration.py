"""Calibrating "not in view": the presence threshold chosen on validation scenes, written to a checkpoint.

The latent planner's presence head gives p(asked-for target in view). At p = 0.5 it called most
absent pairs present, so the loop could not use it. `calibrate_presence` chooses, on validation
folders only (scenes neither the training nor the test sets drew), the highest threshold that calls
at most `max_false_absent` of the present pairs absent (`presence.choose_threshold`), and
`write_presence_threshold` stores it in the checkpoint's config.json (`planner.presence_threshold`,
with a record of how it was chosen). What flies reads that one number
(`controller.planning.latent.planner.LatentPlanner.presence_threshold`); held-out figures come from
`dronectl evaluate --as-flown` on test folders, never from the folders it was chosen on.

The pairs are asked as the loop asks before it takes a detection for the target
(`presence.kind_presence_pairs`: by the kind alone, in the planner's words, with the mirror image
where the checkpoint's planner mirrors): each test image for its named target's kind, for every kind
none of its targets has, and each `empty` image for its named target's kind.
"""

from __future__ import annotations

import datetime
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller.evaluation.presence import (
    PresenceResult,
    choose_threshold,
    judge_presence,
    kind_presence_pairs,
)
from controller.planning.latent.checkpoint import LoadedCheckpoint, load_checkpoint, write_planner_settings
from controller.planning.latent.errors import LatentError
from controller.training.data import ImageSet, load_images, load_index

log = logging.getLogger(__name__)

DEFAULT_MAX_FALSE_ABSENT = 0.02
"""The share of validation present pairs the chosen threshold may call absent. The goal on held-out
scenes is at most 3 %; 2 % on validation leaves about one binomial standard deviation of ~400 pairs."""


class CalibrationError(LatentError):
    """Validation folders that cannot calibrate this checkpoint (trained-on scenes, no pairs); one line."""


@dataclass(frozen=True)
class PresenceCalibration:
    """The chosen threshold and how: the validation folders, the budget, the rates there."""

    threshold: float
    max_false_absent: float
    mirror: bool
    validation: tuple[str, ...]
    result: PresenceResult
    """The validation pairs judged at `threshold` (the rates it was chosen for, not a held-out figure)."""

    def record(self) -> dict[str, Any]:
        """What config.json keeps beside the threshold (`PlannerSettings.presence_calibration`)."""
        return {
            "command": "dronectl calibrate-presence",
            "date": datetime.date.today().isoformat(),
            "validation": list(self.validation),
            "max_false_absent": self.max_false_absent,
            "asked": "by kind, in the planner's words (grounding.presence_query)",
            "mirror": self.mirror,
            "validation_result": asdict(self.result),
        }


def validation_pairs(ckpt: LoadedCheckpoint, data_dir: Path, mirror: bool) -> tuple[np.ndarray, np.ndarray]:
    """p(in view) of one folder's present and absent pairs, asked as the loop asks (see the module
    docstring); `CalibrationError` when the folder has scenes the checkpoint trained on."""
    index = load_index(data_dir)
    trained = set(ckpt.meta.get("dataset", {}).get("meta", {}).get("train_scene_seeds") or [])
    test, empty_rows = index.split("test"), index.split("empty")
    seen = {r.scene_seed for r in (*test, *empty_rows)} & trained
    if seen:
        raise CalibrationError(
            f"{data_dir}: {len(seen)} of its test scenes trained the checkpoint: calibrate on scenes it "
            f"never saw (`dronectl collect` with a seed no training folder used)"
        )
    eps = index.default_epsilon_px()
    size = ckpt.config.image_size
    data = load_images(test, size, eps, desc=f"{data_dir} test")
    if not data.targets or len(data) == 0:
        raise CalibrationError(f"{data_dir}: its test split lists no targets to ask for")
    empty: ImageSet | None = None
    if empty_rows:
        empty = load_images(empty_rows, size, eps, f"{data_dir} empty", in_view_only=False)
    return kind_presence_pairs(ckpt, data, empty, mirror)


def calibrate_presence(
    model_dir: Path,
    data_dirs: Sequence[Path],
    max_false_absent: float = DEFAULT_MAX_FALSE_ABSENT,
    mirror: bool | None = None,
) -> PresenceCalibration:
    """Choose the presence threshold of `model_dir` on the validation folders `data_dirs` (pooled).
    `mirror` None: as the checkpoint's planner runs (`planner.mirror_tta`)."""
    ckpt = load_checkpoint(model_dir)
    if ckpt.model.presence is None:
        raise CalibrationError(f"{model_dir}: the checkpoint has no presence head to calibrate")
    if not 0.0 <= max_false_absent < 1.0:
        raise CalibrationError(f"the false-absent budget must be in [0, 1), got {max_false_absent:g}")
    mirror = ckpt.planner.mirror_tta if mirror is None else mirror
    present, absent = [], []
    for folder in data_dirs:
        p, a = validation_pairs(ckpt, Path(folder), mirror)
        present.append(p)
        absent.append(a)
    p_present, p_absent = np.concatenate(present), np.concatenate(absent)
    threshold = choose_threshold(p_present, p_absent, max_false_absent)
    result = judge_presence(p_present, p_absent, threshold)
    log.info("threshold %.4f on %d present, %d absent pairs", threshold, len(p_present), len(p_absent))
    return PresenceCalibration(threshold, max_false_absent, mirror, tuple(str(d) for d in data_dirs), result)


def write_presence_threshold(model_dir: Path, calibration: PresenceCalibration) -> None:
    """Store the threshold and its record in `model_dir`'s config.json (`planner` section only)."""
    settings = load_checkpoint(model_dir).planner
    updated = settings.model_copy(
        update={"presence_threshold": calibration.threshold, "presence_calibration": calibration.record()}
    )
    write_planner_settings(model_dir, updated)
