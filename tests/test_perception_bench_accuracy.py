"""`dronectl bench perception`'s accuracy: Wilson intervals, the threshold tuner, a tiny bench run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.benchmarks.perception_accuracy import (
    TEST_FIRST_SEED,
    VALIDATION_FIRST_SEED,
    multi_target_figures,
)
from drone_inspect_core.stats import Rate, quantile_interval, wilson_interval
from perception.evaluation.threshold_tuning import at_threshold, tune_threshold, tuning_scores
from perception.image_detector import SHIPPED_DIR
from perception.types import Detection


def test_wilson_interval_known_values() -> None:
    low, high = wilson_interval(97, 100)
    assert low == pytest.approx(0.9155, abs=1e-4) and high == pytest.approx(0.9897, abs=1e-4)
    assert wilson_interval(0, 10) == (0.0, pytest.approx(0.2775, abs=1e-4))
    assert wilson_interval(10, 10) == (pytest.approx(0.7225, abs=1e-4), 1.0)
    assert wilson_interval(0, 0) == (0.0, 1.0)
    # One miss in 83 (today's sample) vs 1,000: the interval narrows about threefold.
    assert wilson_interval(82, 83)[0] < 0.94 < 0.99 < wilson_interval(995, 1000)[0] + 0.005
    with pytest.raises(ValueError):
        wilson_interval(3, 2)
    assert Rate(1, 4).as_dict()["rate"] == 0.25 and Rate(0, 0).as_dict()["rate"] is None


def test_quantile_interval_brackets_the_quantile() -> None:
    values = [float(v) for v in range(1001)]  # median 500
    low, high = quantile_interval(values, 0.5)
    assert 460 < low < 500 < high < 540
    low, high = quantile_interval(values, 0.95)
    assert low < 950 < high <= 1000


def test_tuner_picks_the_highest_recall_within_the_fp_bound() -> None:
    positives = [0.3] * 5 + [0.9] * 995  # five weak hits
    negatives = [0.0] * 396 + [0.2, 0.25, 0.55, 0.7]  # 400 empties; 0.5 % allows 2 false alarms
    choice = tune_threshold(positives, negatives, max_fp_rate=0.005)
    # 0.26 .. 0.30 keep 2 false alarms and every hit; of equal recalls the middle threshold.
    assert choice.threshold == 0.28 and choice.feasible
    assert (choice.recall.hits, choice.false_positives.hits) == (1000, 2)
    strict = tune_threshold(positives, negatives, max_fp_rate=0.0)
    assert strict.threshold == 0.81 and strict.recall.hits == 995 and strict.false_positives.hits == 0
    hopeless = tune_threshold([0.9], [0.99], max_fp_rate=0.0)
    assert not hopeless.feasible and hopeless.threshold == 0.95


def _det(u: float, v: float, conf: float, kind: str = "gauge") -> Detection:
    return Detection(bbox_px=(u - 5, v - 5, u + 5, v + 5), centre_px=(u, v), confidence=conf, kind=kind)


def test_tuning_scores_and_rethresholding() -> None:
    full = {"split": "test", "in_view": True, "fully_in_view": True, "bbox_px": [0, 0, 1, 1],
            "centre_px": [50.0, 50.0]}  # fmt: skip
    rows = [full, full, {**full, "fully_in_view": False}, {"split": "empty"}, {"split": "empty"}]
    dets = [_det(51, 50, 0.8), _det(90, 90, 0.9), _det(50, 50, 0.99), _det(10, 10, 0.3), None]
    positives, negatives = tuning_scores(rows, dets, match_px=10.0)
    assert positives == [0.8, 0.0]  # the second one's strongest peak is elsewhere: never a hit
    assert negatives == [0.3, 0.0]
    assert at_threshold(dets, 0.85) == [None, dets[1], dets[2], None, None]


def test_multi_target_matching_counts_every_fully_visible_target() -> None:
    def truth(u: float, kind: str, full: bool = True) -> dict:
        return {"kind": kind, "attribute": "red", "in_view": True, "fully_in_view": full,
                "bbox_px": [0, 0, 1, 1], "centre_px": [u, 100.0]}  # fmt: skip

    rows = [{"targets": [truth(50, "gauge"), truth(120, "valve"), truth(200, "gauge", full=False)]}]
    found = [[_det(52, 100, 0.9), _det(121, 100, 0.8, kind="gauge"), _det(10, 10, 0.7)]]
    m = multi_target_figures(rows, found, match_px=10.0)
    recall = m["recall_all_fully_in_view_targets"]
    assert (recall["hits"], recall["n"]) == (2, 2)
    assert m["kind_accuracy"]["hits"] == 1 and m["unmatched_detections"] == 1


@pytest.mark.timeout(300)
def test_tiny_bench_writes_intervals_and_tunes_on_validation_only(tmp_path: Path) -> None:
    from dronectl.bench_perception import main

    from controller.benchmarks.perception_accuracy import AccuracySampleSizes, run_accuracy_bench

    out = tmp_path / "bench.json"
    argv = ["--test", "9", "--test-empty", "6", "--validation", "9", "--validation-empty", "6",
            "--frames", "5", "--stream-frames", "0", "--workers", "1", "--work-dir", str(tmp_path / "w"),
            "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    result = json.loads(out.read_text())
    acc = result["accuracy"]
    assert acc["scene_seeds"]["validation_from"] == VALIDATION_FIRST_SEED == 2**31
    for name in ("test_at_tuned", "test_at_shipped"):
        recall = acc[name]["recall_fully_in_view"]
        assert 0.0 <= recall["ci95"][0] <= recall["ci95"][1] <= 1.0 and recall["n"] >= 1
        assert acc[name]["false_positive_rate_empty"]["n"] == 6
        assert len(acc[name]["centre_error_median_px"]["ci95"]) == 2
    assert acc["test_at_shipped"]["threshold"] == 0.5
    assert set(result["targets_met"]["test_at_tuned"]) >= {
        "recall_ci95_low_ge_0.99",
        "false_positive_ci95_high_le_0.01",
    }
    assert (
        result["targets_met"]["test_at_shipped"]["false_positive_ci95_high_le_0.01"] is False
    )  # 6 empties prove little
    assert {"mean_ms", "p50_ms", "p99_ms", "load_avg_before"} <= set(result["detector_latency_224"])
    test_rows = (tmp_path / "w" / "test" / "manifest.jsonl").read_text().splitlines()
    assert min(json.loads(r)["scene_seed"] for r in test_rows) >= TEST_FIRST_SEED
    # Scoring another test set (here: the validation sample itself) leaves the tuned threshold as it was.
    sizes = AccuracySampleSizes(test=9, test_empty=6, validation=9, validation_empty=6)
    again = run_accuracy_bench(SHIPPED_DIR, tmp_path / "w", sizes, 1, test_dir=tmp_path / "w" / "validation")
    assert again["tuning"] == acc["tuning"]


def test_as_streamed_is_the_picture_a_real_mjpeg_server_sends() -> None:
    """`as_streamed` gives, byte for byte, what the MJPEG server serves at `/frame.jpg`, decoded as the
    stream camera decodes it; a 1 px red line keeps its luma there but loses most of its chroma."""
    import urllib.request

    import cv2
    import numpy as np

    from perception.evaluation.streamed import STREAM_JPEG_QUALITY, as_streamed
    from perception.mjpeg_http import decode_jpeg
    from sim_world.rendering.mjpeg import MjpegServer

    image = np.full((64, 64, 3), (128, 118, 110), np.uint8)
    image[:, 31] = (192, 57, 43)  # a 1 px red trim
    streamed = as_streamed(image)
    with MjpegServer("127.0.0.1", 0, jpeg_quality=STREAM_JPEG_QUALITY) as server:
        server.publish(image)
        with urllib.request.urlopen(f"http://127.0.0.1:{server.port}/frame.jpg", timeout=3.0) as resp:
            served = cv2.cvtColor(decode_jpeg(resp.read()), cv2.COLOR_BGR2RGB)
    assert np.array_equal(served, streamed)

    def ycc(rgb: np.ndarray) -> np.ndarray:  # one pixel's (Y, Cr, Cb)
        return cv2.cvtColor(rgb.reshape(1, 1, 3), cv2.COLOR_RGB2YCrCb).reshape(3).astype(float)

    sent, got = ycc(image[32, 31]), ycc(streamed[32, 31])
    assert abs(got[0] - sent[0]) < 12  # luma: its own
    wall = ycc(image[32, 0])
    assert np.linalg.norm(got[1:] - wall[1:]) < 0.7 * np.linalg.norm(sent[1:] - wall[1:])  # chroma: shared
