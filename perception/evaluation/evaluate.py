"""Accuracy of a detector against the dataset's truth.

The figures the issue asks for, on the held-out `test` split (scene seeds never
trained on) and the `empty` split (rows of the `goal` and `train` splits count
like `test` rows, for validation):

- recall for targets fully in view: a detection whose centre is within
  `match_px` (default ε) of the truth centre;
- centre error (median, 95th percentile, max) over fully-in-view targets detected at all;
- false-positive rate on `empty` images (any detection is a false positive);
- wrong confident boxes: detections on `test` rows whose target is not there or
  whose centre is more than `match_px` off (partly visible and absent targets included);
- agreement of the centring test on the detection with the truth label
  (centred ⇔ |du| ≤ ε and |dv| ≤ ε on the truth offset; out-of-view ⇒ not centred).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from drone_inspect_core.centring import default_epsilon_px, is_centred
from drone_inspect_core.dataset import DatasetError, is_held_out, load_manifest, read_image_rgb
from drone_inspect_core.stats import Rate, quantile_interval
from perception.detector import Detector
from perception.types import Detection


@dataclass(frozen=True)
class DetectorMetrics:
    """Accuracy figures; rates are fractions in [0, 1], errors in pixels of the evaluated images."""

    epsilon_px: float
    match_px: float
    n_fully_in_view: int
    recall_fully_in_view: float
    centre_error_median_px: float
    centre_error_p95_px: float
    centre_error_max_px: float
    n_partly_in_view: int
    recall_partly_in_view: float
    n_out_of_view: int
    n_wrong_confident: int
    n_empty: int
    false_positive_rate_empty: float
    kind_accuracy: float
    n_centring: int
    centring_agreement: float
    hits_fully_in_view: int = 0
    n_false_positive_empty: int = 0
    n_kind: int = 0
    """Detections matched to a fully or partly visible target whose kind was judged."""
    kind_hits: int = 0
    centre_errors_px: tuple[float, ...] = field(default=(), repr=False)
    """The centre error of every fully-in-view target detected at all (for the quantile intervals)."""

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON; an undefined figure (no rows of its kind) is None, not NaN."""
        values = asdict(self)
        del values["centre_errors_px"]
        return {k: None if isinstance(v, float) and np.isnan(v) else v for k, v in values.items()}

    def intervals(self) -> dict[str, Any]:
        """The rates with their 95 % Wilson intervals, the centre-error quantiles with theirs."""
        return {
            "recall_fully_in_view": Rate(self.hits_fully_in_view, self.n_fully_in_view).as_dict(),
            "false_positive_rate_empty": Rate(self.n_false_positive_empty, self.n_empty).as_dict(),
            "kind_accuracy": Rate(self.kind_hits, self.n_kind).as_dict(),
            "centre_error_median_px": {
                "value": _finite(self.centre_error_median_px),
                "ci95": [_finite(x) for x in quantile_interval(self.centre_errors_px or [np.nan], 0.5)],
            },
            "centre_error_p95_px": {
                "value": _finite(self.centre_error_p95_px),
                "ci95": [_finite(x) for x in quantile_interval(self.centre_errors_px or [np.nan], 0.95)],
            },
        }

    def summary(self) -> str:
        return (
            f"recall(full) {self.recall_fully_in_view:.4f} on {self.n_fully_in_view}, "
            f"centre err median {self.centre_error_median_px:.2f} px p95 {self.centre_error_p95_px:.2f} px "
            f"max {self.centre_error_max_px:.1f} px, recall(partial) {self.recall_partly_in_view:.3f} on "
            f"{self.n_partly_in_view}, wrong confident {self.n_wrong_confident}, "
            f"FP(empty) {self.false_positive_rate_empty:.4f} on {self.n_empty}, "
            f"kind acc {self.kind_accuracy:.3f}, "
            f"centring agreement {self.centring_agreement:.4f} on {self.n_centring}"
        )


def _finite(x: float) -> float | None:
    return None if np.isnan(x) else float(x)


def _rate(hits: int, total: int) -> float:
    return hits / total if total else float("nan")


def truth_is_centred(row: dict[str, Any], epsilon_px: float) -> bool:
    """The truth label: centred exactly when `label_from_offset(du, dv, ε)` is (none, none)."""
    du, dv = row["offset_px"]
    return bool(row["in_view"]) and abs(du) <= epsilon_px and abs(dv) <= epsilon_px


def evaluate_detections(
    rows: Sequence[dict[str, Any]],
    detections: Sequence[Detection | None],
    width: int,
    height: int,
    epsilon_px: float,
    match_px: float | None = None,
) -> DetectorMetrics:
    """Score detections against their manifest rows (same order)."""
    if len(rows) != len(detections):
        raise ValueError(f"{len(rows)} rows but {len(detections)} detections")
    match = epsilon_px if match_px is None else match_px
    errors_full: list[float] = []
    hits_full = n_full = hits_partial = n_partial = n_out = wrong = 0
    fp_empty = n_empty = kind_hits = kind_total = agree = n_centring = 0
    for row, det in zip(rows, detections, strict=True):
        if row["split"] == "empty":
            n_empty += 1
            fp_empty += det is not None
        positive = bool(row["in_view"]) and row["bbox_px"] is not None and row["split"] != "empty"
        err = float("inf")
        if det is not None and positive:
            err = float(
                np.hypot(det.centre_px[0] - row["centre_px"][0], det.centre_px[1] - row["centre_px"][1])
            )
        if row["split"] != "empty":
            if positive and row["fully_in_view"]:
                n_full += 1
                hits_full += err <= match
                if det is not None:
                    errors_full.append(err)
            elif positive:
                n_partial += 1
                hits_partial += err <= match
            else:
                n_out += 1
            wrong += det is not None and err > match
            if det is not None and positive and err <= match and det.kind is not None:
                kind_total += 1
                kind_hits += det.kind == row["target_kind"]
        n_centring += 1
        agree += is_centred(det, epsilon_px, width, height) == truth_is_centred(row, epsilon_px)
    errs = np.asarray(errors_full) if errors_full else np.asarray([float("nan")])
    return DetectorMetrics(
        epsilon_px=epsilon_px,
        match_px=match,
        n_fully_in_view=n_full,
        recall_fully_in_view=_rate(hits_full, n_full),
        centre_error_median_px=float(np.median(errs)),
        centre_error_p95_px=float(np.percentile(errs, 95)),
        centre_error_max_px=float(np.max(errs)),
        n_partly_in_view=n_partial,
        recall_partly_in_view=_rate(hits_partial, n_partial),
        n_out_of_view=n_out,
        n_wrong_confident=wrong,
        n_empty=n_empty,
        false_positive_rate_empty=_rate(fp_empty, n_empty),
        kind_accuracy=_rate(kind_hits, kind_total),
        n_centring=n_centring,
        centring_agreement=_rate(agree, n_centring),
        hits_fully_in_view=hits_full,
        n_false_positive_empty=fp_empty,
        n_kind=kind_total,
        kind_hits=kind_hits,
        centre_errors_px=tuple(errors_full),
    )


def latency_ms(fn: Callable[[], object], repeats: int, warmup: int = 10) -> dict[str, float]:
    """Mean, p50 / p90 / p99 and max wall time of `fn()` in milliseconds."""
    for _ in range(warmup):
        fn()
    times = np.empty(repeats)
    for r in range(repeats):
        start = time.perf_counter()
        fn()
        times[r] = time.perf_counter() - start
    times *= 1000.0
    return {
        "mean_ms": float(times.mean()),
        "p50_ms": float(np.percentile(times, 50)),
        "p90_ms": float(np.percentile(times, 90)),
        "p99_ms": float(np.percentile(times, 99)),
        "max_ms": float(times.max()),
        "repeats": repeats,
    }


def select_rows(
    data_dir: str | Path, splits: Sequence[str] = ("test", "empty"), limit_per_split: int | None = None
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The rows to evaluate on and `dataset.json`.

    `empty` rows are taken only from the held-out part (`drone_inspect_core.dataset.is_held_out`: test
    scene seeds, all of them as `dronectl collect` plans them; a flown dataset's test time blocks), so a
    training set's scenes never inflate the figures.
    """
    root = Path(data_dir)
    rows, meta = load_manifest(root)
    chosen: list[dict[str, Any]] = []
    for split in splits:
        picked = [r for r in rows if r["split"] == split and (split != "empty" or is_held_out(r, meta))]
        chosen += picked[:limit_per_split] if limit_per_split is not None else picked
    if not chosen:
        raise DatasetError(f"{root}: no rows in splits {list(splits)}")
    return chosen, meta


def run_detector(
    detector: Detector, data_dir: str | Path, rows: Sequence[dict[str, Any]], batch_size: int = 32
) -> list[Detection | None]:
    """The detector's strongest detection (or None) on each row's image, in row order."""
    root = Path(data_dir)
    detections: list[Detection | None] = []
    detect_batch = getattr(detector, "detect_batch", None)
    for start in tqdm(range(0, len(rows), batch_size), desc=f"evaluate {root.name}", leave=False):
        images = [read_image_rgb(root / r["image"]) for r in rows[start : start + batch_size]]
        detections += detect_batch(images) if detect_batch else [detector.detect(im) for im in images]
    return detections


def image_size_and_epsilon(meta: dict[str, Any]) -> tuple[int, int, float]:
    """(width, height, ε) of a dataset, from its `dataset.json`."""
    width, height = int(meta["camera"]["width"]), int(meta["camera"]["height"])
    return width, height, float(meta.get("epsilon_px") or default_epsilon_px(width))


def evaluate_on_dataset(
    detector: Detector,
    data_dir: str | Path,
    splits: Sequence[str] = ("test", "empty"),
    limit_per_split: int | None = None,
    batch_size: int = 32,
) -> DetectorMetrics:
    """Run a detector on a dataset folder's images (in their own pixels) and score it (`select_rows`)."""
    chosen, meta = select_rows(data_dir, splits, limit_per_split)
    detections = run_detector(detector, data_dir, chosen, batch_size)
    return evaluate_detections(chosen, detections, *image_size_and_epsilon(meta))
