"""Pick the detector's score threshold on a validation sample, never on the test one.

The detector reports a target when its strongest heatmap peak scores at least the
threshold. Each validation image reduces to one number:

- a positive image (the target fully in view): the score at which it counts as found,
  the strongest detection's confidence when that detection is within `match_px` of the
  truth centre, else 0 (no threshold finds it: the strongest peak is elsewhere);
- an empty image: the strongest detection's confidence (0 when none), a false alarm at
  any threshold up to it.

`tune_threshold` then takes, on a fixed grid, the threshold of highest recall whose
false-positive rate is at most `max_fp_rate`; of the thresholds with that recall the
middle one (margin both ways: against false alarms above, against missed weak targets
below, as the test sample will not score exactly as the validation one).

Scores come from a detector run at a low floor threshold: its strongest detection does
not depend on the threshold, so re-thresholding afterwards gives exactly what a detector
built with that threshold returns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drone_inspect_core.stats import Rate
from perception.types import Detection

DEFAULT_GRID = tuple(round(0.05 + 0.01 * i, 2) for i in range(91))
"""0.05, 0.06, …, 0.95."""
SCORE_FLOOR = DEFAULT_GRID[0]
"""The threshold the scoring detector runs at: the lowest on the grid."""


@dataclass(frozen=True)
class ThresholdChoice:
    """The chosen threshold and what it gives on the validation sample."""

    threshold: float
    recall: Rate
    false_positives: Rate
    max_fp_rate: float
    feasible: bool
    """False when no threshold on the grid kept the false-positive rate within `max_fp_rate`
    (the highest threshold is returned then)."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "threshold": self.threshold,
            "recall_fully_in_view": self.recall.as_dict(),
            "false_positive_rate_empty": self.false_positives.as_dict(),
            "max_fp_rate": self.max_fp_rate,
            "feasible": self.feasible,
        }


def tune_threshold(
    positive_scores: Sequence[float],
    negative_scores: Sequence[float],
    max_fp_rate: float = 0.005,
    grid: Sequence[float] = DEFAULT_GRID,
) -> ThresholdChoice:
    """The grid threshold of highest recall with a false-positive rate ≤ `max_fp_rate` (module doc)."""
    if not positive_scores or not negative_scores:
        raise ValueError(
            f"tuning needs positive and empty images, got {len(positive_scores)} and {len(negative_scores)}"
        )
    if not grid:
        raise ValueError("empty threshold grid")
    pos, neg = np.asarray(positive_scores, dtype=float), np.asarray(negative_scores, dtype=float)
    feasible_hits = {
        t: int(np.sum(pos >= t)) for t in sorted(grid) if np.sum(neg >= t) <= max_fp_rate * len(neg)
    }
    feasible = bool(feasible_hits)
    if feasible:
        best = max(feasible_hits.values())
        ties = [t for t, hits in feasible_hits.items() if hits == best]
        threshold = ties[len(ties) // 2]
    else:
        threshold = max(grid)
    return ThresholdChoice(
        threshold=threshold,
        recall=Rate(int(np.sum(pos >= threshold)), len(pos)),
        false_positives=Rate(int(np.sum(neg >= threshold)), len(neg)),
        max_fp_rate=max_fp_rate,
        feasible=feasible,
    )


def tuning_scores(
    rows: Sequence[dict[str, Any]], detections: Sequence[Detection | None], match_px: float
) -> tuple[list[float], list[float]]:
    """(positive scores, negative scores) of a sample's fully-in-view and empty rows (module doc)."""
    positives: list[float] = []
    negatives: list[float] = []
    for row, det in zip(rows, detections, strict=True):
        score = det.confidence if det is not None else 0.0
        if row["split"] == "empty":
            negatives.append(score)
        elif row["in_view"] and row["fully_in_view"] and row["bbox_px"] is not None:
            near = det is not None and (
                np.hypot(det.centre_px[0] - row["centre_px"][0], det.centre_px[1] - row["centre_px"][1])
                <= match_px
            )
            positives.append(score if near else 0.0)
    return positives, negatives


def at_threshold(detections: Sequence[Detection | None], threshold: float) -> list[Detection | None]:
    """What a detector built with `threshold` returns, from detections made at a lower floor."""
    return [d if d is not None and d.confidence >= threshold else None for d in detections]


def all_at_threshold(detections: Sequence[Sequence[Detection]], threshold: float) -> list[list[Detection]]:
    """`at_threshold` for `detect_all`'s lists (a peak kept at the floor stays kept above it)."""
    return [[d for d in found if d.confidence >= threshold] for found in detections]
