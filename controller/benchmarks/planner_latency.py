"""Planner latency per decision (one image encoding + all 9 candidates), as `dronectl evaluate --latency`."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from controller.training.data import load_index, read_image
from controller.training.instructions import builtin_templates, fill
from controller.planning.latent.planner import LatentPlanner
from drone_inspect_core.onnx_runtime import time_side_by_side

FIXED_INSTRUCTION = fill(builtin_templates("fixed")[0], "gauge")


@dataclass(frozen=True)
class Latency:
    decisions: int
    mean_ms: float
    p50_ms: float
    p99_ms: float
    max_ms: float
    backend: str = "torch"  # "torch" or "onnx": what the planner ran on


def measure_latency(
    planner: LatentPlanner,
    images: Sequence[np.ndarray],
    instruction: str,
    decisions: int = 500,
    warmup: int = 20,
) -> Latency:
    """Time `planner.plan` on `decisions` calls cycling over `images` (full-size camera frames)."""
    if not images:
        raise ValueError("measure_latency needs at least one image")
    for i in range(warmup):
        planner.plan(images[i % len(images)], instruction)
    times = np.empty(decisions)
    for i in range(decisions):
        start = time.perf_counter()
        planner.plan(images[i % len(images)], instruction)
        times[i] = time.perf_counter() - start
    ms = times * 1e3
    return Latency(
        decisions,
        float(ms.mean()),
        *(float(np.percentile(ms, q)) for q in (50, 99)),
        float(ms.max()),
        planner.backend,
    )


def latency_on_dataset(
    model_dir: Path,
    data_dir: Path,
    split: str = "test",
    decisions: int = 500,
    threads: int = 1,
    backend: str = "auto",
) -> Latency:
    """Latency on up to 50 full-size frames of a dataset split, with the fixed instruction.

    `backend` as `LatentPlanner`'s; `Latency.backend` says which one ran.
    """
    planner = LatentPlanner(model_dir, threads=threads, backend=backend)
    return measure_latency(planner, dataset_frames(data_dir, split), FIXED_INSTRUCTION, decisions)


def dataset_frames(data_dir: Path, split: str = "test", count: int = 50) -> list[np.ndarray]:
    """Up to `count` full-size frames of a dataset split (the latency inputs)."""
    index = load_index(data_dir)
    return [read_image(r.image, index.width_px) for r in index.split(split)[:count]]


def compare_backends(
    model_dir: Path, images: Sequence[np.ndarray], instruction: str, decisions: int = 500, threads: int = 1
) -> dict[str, Any]:
    """`plan` on torch and on ONNX Runtime, side by side on the same frames (needs onnxruntime).

    The largest |distance difference| and whether every chosen action agrees, then each backend's
    latency per decision (`drone_inspect_core.onnx_runtime.time_side_by_side`).
    """
    planners = {b: LatentPlanner(model_dir, threads=threads, backend=b) for b in ("torch", "onnx")}
    _, want, _ = planners["torch"].plan_with_presence(images, instruction)
    _, got, _ = planners["onnx"].plan_with_presence(images, instruction)
    calls = {b: partial(_plan_one, p, images, instruction) for b, p in planners.items()}
    return {
        "images": len(images),
        "max_abs_distance_difference": float(np.abs(got - want).max()),
        "same_actions": bool((got.argmin(axis=1) == want.argmin(axis=1)).all()),
        "latency": time_side_by_side(calls, decisions),
    }


def _plan_one(planner: LatentPlanner, images: Sequence[np.ndarray], instruction: str, i: int) -> None:
    planner.plan(images[i % len(images)], instruction)
