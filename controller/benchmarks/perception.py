"""`dronectl bench perception`: detector latency, stream-camera latency and detector accuracy.

- Detector latency per 224 px frame (p50 / p90 / p99), single frames, on
  `--threads` torch threads (default 1: the steadiest on a small shared CPU).
- Stream camera end to end: the simulated world renders a frame, the MJPEG server
  publishes it, a `StreamCamera` on the loopback URL hands it back; render time,
  publish → frame in hand, and the total (p50 / p99).
- Accuracy on a large sample from unseen scenes (`controller.benchmarks.perception_accuracy`): the
  score threshold tuned on a validation sample, the test figures at the tuned and the
  shipped threshold, each with its 95 % interval; optionally recall over every target
  of several-target scenes (`--targets`).

The load average is printed beside the latencies: other work on the machine slows them.

Prints a summary and, with `--json FILE`, writes every figure there.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from drone_inspect_core.onnx_runtime import time_side_by_side
from perception.evaluation.evaluate import latency_ms, read_image_rgb
from perception.errors import CameraTimeoutError
from perception.image_detector import ImageDetector
from perception.stream_camera import StreamCamera

log = logging.getLogger(__name__)

DETECTOR_P99_TARGET_MS = 10.0
STREAM_TARGET_MS = 100.0


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


def sample_images(data_dir: Path, count: int) -> list[np.ndarray]:
    """The first `count` test and empty images of a dataset folder (latency inputs)."""
    from drone_inspect_core.dataset import load_manifest

    rows, _ = load_manifest(data_dir)
    picked = [r for r in rows if r["split"] in ("test", "empty")][:count]
    return [read_image_rgb(data_dir / r["image"]) for r in picked]


def compare_detector_backends(
    weights: Path, images: list[np.ndarray], frames: int, threads: int = 1
) -> dict[str, Any]:
    """`detect` on torch and on ONNX Runtime, side by side on the same frames (needs onnxruntime).

    The largest |head output difference| (heatmap logits, offsets, log edges), whether every
    detection's kind agrees, then each backend's latency per frame.
    """
    import torch

    detectors = {b: ImageDetector.load(weights, backend=b, threads=threads) for b in ("torch", "onnx")}
    with torch.inference_mode():
        want, got = (detectors[b]._forward(images).numpy() for b in ("torch", "onnx"))
    kinds = [[None if d is None else d.kind for d in detectors[b].detect_batch(images)] for b in detectors]

    def call(detector: ImageDetector, i: int) -> None:
        detector.detect(images[i % len(images)])

    calls = {b: partial(call, d) for b, d in detectors.items()}
    return {
        "images": len(images),
        "max_abs_head_difference": float(np.abs(got - want).max()),
        "same_kinds": kinds[0] == kinds[1],
        "latency": time_side_by_side(calls, frames),
    }
