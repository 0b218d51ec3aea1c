"""`dronectl bench perception`: detector latency, stream-camera latency and detector accuracy.

- Detector latency per 224 px frame (p50 / p90 / p99), single frames, on
  `--threads` torch threads (default 1: the steadiest on a small shared CPU).
- Stream camera end to end: the simulated world renders a frame, the MJPEG server
  publishes it, a `StreamCamera` on the loopback URL hands it back; render time,
  publish → frame in hand, and the total (p50 / p99).
- Accuracy on a dataset's held-out `test` split and its `empty` images (`--data`),
  or on a small dataset collected on the spot into a temporary folder.

Prints a summary and, with `--json FILE`, writes every figure there.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import torch

from perception.detector_eval import evaluate_on_dataset, latency_ms, read_image_rgb
from perception.errors import CameraTimeoutError
from perception.image_detector import SHIPPED_DIR, ImageDetector
from perception.stream_camera import StreamCamera

log = logging.getLogger(__name__)

DETECTOR_P99_TARGET_MS = 10.0
STREAM_TARGET_MS = 100.0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dronectl bench perception",
        description=__doc__,
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


def _sim_world(seed: int) -> Any:
    from sim_world.world import World  # imported here: pybullet only when benchmarking the sim

    world = World(seed=seed)
    position, yaw = world.scene.pose_for_offset(0.0, 0.0, 2.0, 0.0)
    world.teleport(position, yaw)
    return world


def bench_detector_latency(
    detector: ImageDetector, images: list[np.ndarray], frames: int
) -> dict[str, float]:
    counter = iter(range(10**9))
    return latency_ms(lambda: detector.detect(images[next(counter) % len(images)]), repeats=frames)


def bench_stream(seed: int, frames: int) -> dict[str, Any]:
    """Render → publish → StreamCamera.read(), one frame in flight at a time, over loopback."""
    from sim_world.rendering.mjpeg import MjpegServer

    render_ms, transit_ms, total_ms = [], [], []
    with _sim_world(seed) as world, MjpegServer(port=0) as server:
        stop = threading.Event()

        def keep_publishing() -> None:  # FFmpeg reads a few frames while it opens the stream
            while not stop.is_set():
                server.publish(world.render(with_seg=False).rgb)
                stop.wait(0.03)

        with ThreadPoolExecutor(1) as pool:
            publisher = pool.submit(keep_publishing)
            try:
                camera = StreamCamera(server.stream_url, timeout_s=2.0, open_timeout_s=5.0)
            finally:
                stop.set()
                publisher.result()
        with camera:
            time.sleep(0.2)
            while True:  # drain what arrived while opening
                try:
                    camera.read(timeout_s=0.1)
                except CameraTimeoutError:
                    break
            for _ in range(frames):
                start = time.perf_counter()
                rgb = world.render(with_seg=False).rgb
                published = time.perf_counter()
                server.publish(rgb)
                frame = camera.read(timeout_s=2.0)
                done = time.perf_counter()
                if frame.image.shape != rgb.shape:
                    raise RuntimeError(f"stream frame shape {frame.image.shape} != rendered {rgb.shape}")
                render_ms.append((published - start) * 1e3)
                transit_ms.append((done - published) * 1e3)
                total_ms.append((done - start) * 1e3)

    def stats(values: list[float]) -> dict[str, float]:
        return {
            "p50_ms": float(np.percentile(values, 50)),
            "p99_ms": float(np.percentile(values, 99)),
            "max_ms": float(np.max(values)),
        }

    return {
        "frames": frames,
        "render": stats(render_ms),
        "publish_to_frame_in_hand": stats(transit_ms),
        "render_to_frame_in_hand": stats(total_ms),
    }


def collect_small_dataset(out_dir: Path, seed: int) -> Path:
    """A small held-out set: 90 test images (10 per class) and 30 empty ones."""
    from sim_world.collection.collect import CollectConfig, collect

    collect(
        CollectConfig(
            out_dir=out_dir, seed=seed, n_goal=1, n_per_sector=0, n_test=90, n_empty=30, images_per_scene=10
        ),
        progress=False,
    )
    return out_dir


def bench_main(argv: list[str]) -> int:
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


def _sample_images(data_dir: Path, count: int) -> list[np.ndarray]:
    from core.dataset import load_manifest

    rows, _ = load_manifest(data_dir)
    picked = [r for r in rows if r["split"] in ("test", "empty")][:count]
    return [read_image_rgb(data_dir / r["image"]) for r in picked]
