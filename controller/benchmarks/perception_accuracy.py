"""The accuracy half of `dronectl bench perception`: a large sample from unseen scenes.

Samples are rendered with `dronectl collect`'s machinery (`plan_held_out`: test images
cycling over the centre and the eight sectors, and empty views) on scene seeds of their
own, at and above 2**31. `dronectl collect` draws every scene seed below 2**31 − 1, so no
collected dataset, and so no training set of the shipped detector, holds these scenes:

- validation (threshold tuning): scene seeds from `VALIDATION_FIRST_SEED`;
- test (the reported figures): scene seeds from `TEST_FIRST_SEED`;
- several targets per scene (`targets`): scene seeds from `MULTI_FIRST_SEED`.

The threshold is tuned on validation only (`threshold_tuning`); the test figures are
reported at the tuned threshold and at the shipped one, every rate with its 95 % Wilson
interval and the centre-error quantiles with theirs.

The several-target sample is also scored as a stream camera receives it
(`perception.evaluation.streamed.as_streamed`): each picture JPEG-encoded as the simulated vehicle's
MJPEG stream sends it and decoded as the stream camera decodes it, where a thin trim keeps its luma
but not its chroma. Its colours are also read by the rule reader alone (`perception.attributes`, the
detector's colour reader set aside), lossless and through the stream, beside the learned reader's
(`perception.colour_model`) that the detector uses.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drone_inspect_core.dataset import DATASET_JSON, read_image_rgb
from drone_inspect_core.stats import Rate
from perception.evaluation.evaluate import (
    evaluate_detections,
    image_size_and_epsilon,
    run_detector,
    select_rows,
)
from perception.evaluation.streamed import STREAM_JPEG_QUALITY, as_streamed
from perception.evaluation.threshold_tuning import (
    SCORE_FLOOR,
    all_at_threshold,
    at_threshold,
    tune_threshold,
    tuning_scores,
)
from perception.image_detector import ImageDetector
from perception.types import Detection

log = logging.getLogger(__name__)

VALIDATION_FIRST_SEED = 2**31
TEST_FIRST_SEED = 2**31 + 1_000_000
MULTI_FIRST_SEED = 2**31 + 2_000_000


@dataclass(frozen=True)
class AccuracySampleSizes:
    """Images per sample (defaults: ≥ 1,000 test images with the target in view, ≥ 300 empty)."""

    test: int = 1200
    test_empty: int = 400
    validation: int = 500
    validation_empty: int = 1000
    multi: int = 300
    images_per_scene: int = 5

    def __post_init__(self) -> None:
        for name in ("test", "validation", "images_per_scene"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("test_empty", "validation_empty", "multi"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


def ensure_sample(
    out_dir: Path,
    first_scene_seed: int,
    n_test: int,
    n_empty: int,
    images_per_scene: int,
    workers: int,
    targets: tuple[int, int] | None = None,
) -> Path:
    """Render test and empty images on the scene seeds from `first_scene_seed` into `out_dir`.

    A complete sample of the same plan already there is reused (`--work-dir` keeps samples
    between runs); anything else there is an error (`prepare_output_dir`).
    """
    from sim_world.collection.collect import CollectConfig, collect, plan_held_out
    from sim_world.scene.config import DEFAULT_SCENE, with_targets

    scene = DEFAULT_SCENE if targets is None else with_targets(DEFAULT_SCENE, count=targets)
    cfg = CollectConfig(
        out_dir=out_dir,
        seed=first_scene_seed,
        scene=scene,
        n_goal=1,
        n_per_sector=0,
        n_test=n_test,
        n_empty=n_empty,
        images_per_scene=images_per_scene,
        workers=workers,
    )
    plan = plan_held_out(cfg, first_scene_seed)
    if (out_dir / DATASET_JSON).exists():
        meta = json.loads((out_dir / DATASET_JSON).read_text(encoding="utf-8"))
        planned = {split: n for split, n in (("test", n_test), ("empty", n_empty)) if n}
        same_plan = meta.get("test_scene_seeds") == list(plan.test_scene_seeds)
        same_plan = same_plan and meta.get("planned_counts") == planned
        if meta.get("complete") and same_plan and meta.get("scene_config") == scene.model_dump(mode="json"):
            log.info("reusing the sample in %s", out_dir)
            return out_dir
    result = collect(cfg, progress=True, plan=plan)
    log.info("rendered %s: %s in %.1f s", out_dir, result.counts, result.seconds)
    return out_dir


def _scored(model_dir: Path, data_dir: Path) -> tuple[list[dict[str, Any]], dict[str, Any], list]:
    rows, meta = select_rows(data_dir)
    detections = run_detector(ImageDetector.load(model_dir, SCORE_FLOOR), data_dir, rows)
    return rows, meta, detections


def _figures(
    rows: list[dict[str, Any]], meta: dict[str, Any], detections: list[Detection | None], threshold: float
) -> dict[str, Any]:
    metrics = evaluate_detections(rows, at_threshold(detections, threshold), *image_size_and_epsilon(meta))
    return {"threshold": threshold, "summary": metrics.summary(), **metrics.intervals(),
            "all": metrics.as_dict()}  # fmt: skip


def multi_target_figures(
    rows: list[dict[str, Any]], found: list[list[Detection]], match_px: float
) -> dict[str, Any]:
    """Recall over every fully-in-view target of several-target rows, kind and attribute accuracy of
    the matched ones, and detections matched to no target in view (greedy, nearest pairs first)."""
    hits = n = kind_hits = attr_hits = n_attr = unmatched = 0
    for row, dets in zip(rows, found, strict=True):
        truths = [t for t in row.get("targets", []) if t["in_view"] and t["bbox_px"] is not None]
        pairs = sorted(
            (float(np.hypot(d.centre_px[0] - t["centre_px"][0], d.centre_px[1] - t["centre_px"][1])), i, j)
            for i, d in enumerate(dets)
            for j, t in enumerate(truths)
        )
        used_d: set[int] = set()
        match_of: dict[int, int] = {}
        for dist, i, j in pairs:
            if dist <= match_px and i not in used_d and j not in match_of:
                used_d.add(i)
                match_of[j] = i
        unmatched += len(dets) - len(used_d)
        for j, truth in enumerate(truths):
            if not truth["fully_in_view"]:
                continue
            n += 1
            if j in match_of:
                det = dets[match_of[j]]
                hits += 1
                kind_hits += det.kind == truth["kind"]
                if truth.get("attribute") is not None:
                    n_attr += 1
                    attr_hits += det.attribute == truth["attribute"]
    return {
        "images": len(rows),
        "match_px": match_px,
        "recall_all_fully_in_view_targets": Rate(hits, n).as_dict(),
        "kind_accuracy": Rate(kind_hits, hits).as_dict(),
        "attribute_accuracy": Rate(attr_hits, n_attr).as_dict(),
        "unmatched_detections": unmatched,
    }


def run_accuracy_bench(
    model_dir: Path,
    work_dir: Path,
    sizes: AccuracySampleSizes,
    workers: int,
    max_fp_rate: float = 0.005,
    targets: tuple[int, int] | None = None,
    test_dir: Path | None = None,
) -> dict[str, Any]:
    """Render the samples into `work_dir` (reused when already there), tune, and score (module doc).

    `test_dir`: score a dataset's `test` and `empty` splits instead of rendering the test sample.
    """
    shipped = ImageDetector.load(model_dir).score_threshold
    dirs = {"validation": work_dir / "validation", "test": test_dir or work_dir / "test"}
    plans = {
        "validation": (VALIDATION_FIRST_SEED, sizes.validation, sizes.validation_empty),
        "test": (TEST_FIRST_SEED, sizes.test, sizes.test_empty),
    }
    for name, (first_seed, n_test, n_empty) in plans.items():
        if name == "validation" or test_dir is None:
            ensure_sample(dirs[name], first_seed, n_test, n_empty, sizes.images_per_scene, workers)
    val_rows, val_meta, val_dets = _scored(model_dir, dirs["validation"])
    match_px = image_size_and_epsilon(val_meta)[2]
    choice = tune_threshold(*tuning_scores(val_rows, val_dets, match_px), max_fp_rate=max_fp_rate)
    log.info("tuned score threshold %.2f on validation (shipped %.2f)", choice.threshold, shipped)
    rows, meta, dets = _scored(model_dir, dirs["test"])
    result: dict[str, Any] = {
        "scene_seeds": {
            "validation_from": VALIDATION_FIRST_SEED,
            "test_from": TEST_FIRST_SEED if test_dir is None else f"the test split of {test_dir}",
            "why_unseen": "dronectl collect draws scene seeds below 2**31 - 1; these are at or above 2**31",
        },
        "tuning": {**choice.as_dict(), "validation_images": len(val_rows), "rule": (
            f"highest validation recall with FP <= {max_fp_rate:g}; the middle of the thresholds giving it")},
        "test_at_tuned": _figures(rows, meta, dets, choice.threshold),
        "test_at_shipped": _figures(rows, meta, dets, shipped),
    }  # fmt: skip
    if targets is not None:
        multi_dir = work_dir / f"multi_{targets[0]}-{targets[1]}"
        ensure_sample(multi_dir, MULTI_FIRST_SEED, sizes.multi, 0, sizes.images_per_scene, workers, targets)
        multi_rows, _ = select_rows(multi_dir, splits=("test",))
        floor = ImageDetector.load(model_dir, SCORE_FLOOR)
        found = run_detector_all(floor, multi_dir, multi_rows)
        result["multi_target"] = {
            "targets": list(targets),
            "at_tuned": multi_target_figures(multi_rows, all_at_threshold(found, choice.threshold), match_px),
            "at_shipped": multi_target_figures(multi_rows, all_at_threshold(found, shipped), match_px),
        }
        streamed = run_detector_all(floor, multi_dir, multi_rows, through_stream=True)
        result["multi_target"]["through_the_stream"] = {
            "jpeg_quality": STREAM_JPEG_QUALITY,
            **multi_target_figures(multi_rows, all_at_threshold(streamed, shipped), match_px),
            "threshold": shipped,
        }
        rules = ImageDetector.load(model_dir, SCORE_FLOOR)
        rules.colour_reader = None  # the rule reader alone (`perception.attributes`), for comparison
        for name, through_stream in (("rule_reader", False), ("rule_reader_through_the_stream", True)):
            read = run_detector_all(rules, multi_dir, multi_rows, through_stream=through_stream)
            figures = multi_target_figures(multi_rows, all_at_threshold(read, shipped), match_px)
            result["multi_target"][name] = {
                "attribute_accuracy": figures["attribute_accuracy"],
                "threshold": shipped,
            }
    return result


def run_detector_all(
    detector: ImageDetector,
    data_dir: Path,
    rows: list[dict[str, Any]],
    batch_size: int = 32,
    through_stream: bool = False,
) -> list[list[Detection]]:
    """`detect_all` on each row's image, in row order; `through_stream`: on `as_streamed` copies."""
    found: list[list[Detection]] = []
    for start in range(0, len(rows), batch_size):
        images = [read_image_rgb(data_dir / r["image"]) for r in rows[start : start + batch_size]]
        found += detector.detect_all_batch([as_streamed(i) for i in images] if through_stream else images)
    return found
