"""Calibrating "not in view": the presence threshold chosen on validation scenes as the loop decides,
written to a checkpoint.

The centring loop takes a detection for the named target only when the detector sees one of its kind
(among twins, of its colour) and the latent planner's presence head, asked by the kind alone on the
picture it would see (the other targets of that kind painted over), gives p(in view) at or above the
checkpoint's threshold (`controller.planning.loop`, `CentringLoop._confirm`). `calibrate_presence`
makes exactly those reads on validation folders (scenes neither the training nor the test sets drew)
through `with_detector.evaluate_with_detector`: each test image for its named target, and for every
kind none of its targets has. It chooses the threshold at which the loop makes the fewest wrong calls
there: present targets called absent plus absent ones called present, each as a share of its pairs
(`presence.fewest_errors_threshold`). A pair the detector matches nothing for is absent whatever the
threshold: the head is asked only where the detector matched, so its threshold is chosen on those
reads, and the detector it was chosen with is recorded beside it. `write_presence_threshold` stores the
threshold in the checkpoint's config.json (`planner.presence_threshold`, with how it was chosen). What
flies reads that one number (`controller.planning.latent.planner.LatentPlanner.presence_threshold`);
held-out figures come from `dronectl evaluate --with-detector` on test folders, never from the folders
it was chosen on.

Until 2026-11-27 the threshold was chosen on the head alone (every pair, as if the detector had matched
each): the highest that called at most 2 % of present pairs absent, 0.951. The head then turned away
4 to 18 % of the present targets the detector had found on held-out sets, while the detector alone
already took 0-2 % of the absent kinds (docs/targets.md, "Not in view").
"""

from __future__ import annotations

import datetime
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from controller.evaluation.presence import fewest_errors_threshold
from controller.evaluation.with_detector import evaluate_with_detector, loop_rates
from controller.planning.latent.checkpoint import load_checkpoint, write_planner_settings
from controller.planning.latent.errors import LatentError
from controller.training.data import load_index
from perception.detector import Detector

log = logging.getLogger(__name__)
RULE = (
    "fewest wrong calls of the loop's decision (the detector's match, then p(kind in view) by kind): "
    "present called absent + absent called present, as shares"
)


class CalibrationError(LatentError):
    """Validation folders that cannot calibrate this checkpoint (trained-on scenes, no pairs); one line."""


@dataclass(frozen=True)
class LoopPresence:
    """The loop's "not in view" on validation pairs at one threshold (rates the threshold was chosen
    for, not held-out figures)."""

    threshold: float
    n_present: int
    n_absent: int
    present_unmatched: int
    """Present pairs the detector matched nothing for: called absent whatever the threshold."""
    absent_matched: int
    """Absent pairs the detector matched something for: the only ones the threshold can turn away."""
    false_absent_rate: float
    false_present_rate: float


@dataclass(frozen=True)
class PresenceCalibration:
    """The chosen threshold and how: the validation folders, the detector, the rates there."""

    threshold: float
    mirror: bool
    validation: tuple[str, ...]
    detector: str
    result: LoopPresence

    def record(self) -> dict[str, Any]:
        """What config.json keeps beside the threshold (`PlannerSettings.presence_calibration`)."""
        return {
            "command": "dronectl calibrate-presence",
            "date": datetime.date.today().isoformat(),
            "validation": list(self.validation),
            "rule": RULE,
            "detector": self.detector,
            "asked": "by kind, in the planner's words (grounding.presence_query), where the detector matched",
            "mirror": self.mirror,
            "validation_result": asdict(self.result),
        }


def _refuse_trained_scenes(trained: set[int], data_dir: Path) -> None:
    index = load_index(data_dir)
    seen = {r.scene_seed for r in (*index.split("test"), *index.split("empty"))} & trained
    if seen:
        raise CalibrationError(
            f"{data_dir}: {len(seen)} of its test scenes trained the checkpoint: calibrate on scenes it "
            f"never saw (`dronectl collect` with a seed no training folder used)"
        )


def calibrate_presence(
    model_dir: Path, data_dirs: Sequence[Path], detector: Detector, detector_name: str
) -> PresenceCalibration:
    """Choose the presence threshold of `model_dir` on the validation folders `data_dirs` (pooled), read
    as the loop reads them with `detector` (`detector_name` says which, for the record)."""
    ckpt = load_checkpoint(model_dir)
    if ckpt.model.presence is None:
        raise CalibrationError(f"{model_dir}: the checkpoint has no presence head to calibrate")
    trained = set(ckpt.meta.get("dataset", {}).get("meta", {}).get("train_scene_seeds") or [])
    for folder in data_dirs:
        _refuse_trained_scenes(trained, Path(folder))
    present: list[float | None] = []
    absent: list[float | None] = []
    for folder in data_dirs:
        try:
            result = evaluate_with_detector(model_dir, Path(folder), detector)
        except ValueError as exc:  # a folder without an image whose named target is in view
            raise CalibrationError(str(exc)) from None
        present += result.present_presence
        absent += result.absent_presence
    if not absent:
        raise CalibrationError(
            f"{', '.join(map(str, data_dirs))}: no image lacks a kind to ask for (absent pairs); add a "
            "folder of 1-4-target scenes"
        )
    threshold = fewest_errors_threshold(present, absent)
    false_absent, false_present = loop_rates(present, absent, threshold)
    judged = LoopPresence(
        threshold=threshold,
        n_present=len(present),
        n_absent=len(absent),
        present_unmatched=sum(p is None for p in present),
        absent_matched=sum(p is not None for p in absent),
        false_absent_rate=false_absent,
        false_present_rate=false_present,
    )
    log.info("threshold %.4f on %d present, %d absent pairs", threshold, len(present), len(absent))
    return PresenceCalibration(
        threshold, ckpt.planner.mirror_tta, tuple(str(d) for d in data_dirs), detector_name, judged
    )


def write_presence_threshold(model_dir: Path, calibration: PresenceCalibration) -> None:
    """Store the threshold and its record in `model_dir`'s config.json (`planner` section only)."""
    settings = load_checkpoint(model_dir).planner
    updated = settings.model_copy(
        update={"presence_threshold": calibration.threshold, "presence_calibration": calibration.record()}
    )
    write_planner_settings(model_dir, updated)
