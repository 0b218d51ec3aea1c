"""`dronectl bench perception`: detector latency and accuracy, stream-camera latency (`perception.bench`)."""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path
from typing import Any

import torch

import perception.bench as bench
from perception.bench import (
    DETECTOR_P99_TARGET_MS,
    STREAM_TARGET_MS,
    _sample_images,
    bench_detector_latency,
    bench_stream,
    collect_small_dataset,
)
from perception.detector_eval import evaluate_on_dataset
from perception.image_detector import SHIPPED_DIR, ImageDetector


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dronectl bench perception",
        description=bench.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--json", type=Path, default=None, help="write the figures to this JSON file")
    p.add_argument("--data", type=Path, default=None, help="dataset folder (default: collect a small one)")
    p.add_argument("--weights", type=Path, default=SHIPPED_DIR, help="detector run folder (default: shipped)")
    p.add_argument("--threads", type=int, default=1, help="torch threads for the detector")
    p.add_argument("--frames", type=int, default=300, help="frames timed for the detector latency")
    p.add_argument("--stream-frames", type=int, default=100, help="frames timed through the MJPEG stream")
    p.add_argument("--seed", type=int, default=1234, help="seed of the sim scene and of a collected dataset")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    torch.set_num_threads(args.threads)
    detector = ImageDetector.load(args.weights)
    results: dict[str, Any] = {
        "machine": {
            "cpu_count": os.cpu_count(),
            "processor": platform.processor() or platform.machine(),
            "torch_threads": args.threads,
            "load_avg_1min": os.getloadavg()[0],
        },
        "weights": str(args.weights),
    }
    with tempfile.TemporaryDirectory(prefix="bench_perception_") as tmp:
        data_dir = args.data or collect_small_dataset(Path(tmp) / "data", args.seed)
        results["data"] = str(args.data) if args.data else f"collected on the spot (seed {args.seed})"
        metrics = evaluate_on_dataset(detector, data_dir)
        images = _sample_images(data_dir, 64)
    results["accuracy"] = metrics.as_dict()
    lat = bench_detector_latency(detector, images, args.frames)
    results["detector_latency_224"] = lat
    results["stream"] = bench_stream(args.seed, args.stream_frames)
    stream = results["stream"]["render_to_frame_in_hand"]
    results["targets_met"] = {
        "detector_p99_le_10ms": lat["p99_ms"] <= DETECTOR_P99_TARGET_MS,
        "stream_p99_le_100ms": stream["p99_ms"] <= STREAM_TARGET_MS,
        "recall_fully_in_view_ge_0.99": metrics.recall_fully_in_view >= 0.99,
        "centre_error_median_le_2px": metrics.centre_error_median_px <= 2.0,
        "centre_error_p95_le_5px": metrics.centre_error_p95_px <= 5.0,
        "false_positive_rate_empty_le_0.01": metrics.false_positive_rate_empty <= 0.01,
        "centring_agreement_ge_0.99": metrics.centring_agreement >= 0.99,
    }
    print(
        f"detector latency (224 px, {args.threads} thread(s)): p50 {lat['p50_ms']:.2f} ms, "
        f"p99 {lat['p99_ms']:.2f} ms (target p99 <= {DETECTOR_P99_TARGET_MS:g} ms)"
    )
    render, transit = results["stream"]["render"], results["stream"]["publish_to_frame_in_hand"]
    print(
        f"stream camera: render p50 {render['p50_ms']:.1f} ms, publish -> frame in hand p50 "
        f"{transit['p50_ms']:.1f} ms p99 {transit['p99_ms']:.1f} ms, "
        f"render -> frame in hand p50 {stream['p50_ms']:.1f} ms p99 {stream['p99_ms']:.1f} ms "
        f"(target <= {STREAM_TARGET_MS:g} ms)"
    )
    print(f"accuracy ({results['data']}): {metrics.summary()}")
    print(
        "targets met: " + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in results["targets_met"].items())
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    return 0
