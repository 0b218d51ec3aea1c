"""Planner latency per decision (one image encoding + all 9 candidates), as `dronectl evaluate --latency`."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.planning.latent.data import load_index, read_image
from controller.planning.latent.instructions import builtin_templates, fill
from controller.planning.latent.planner import LatentPlanner


@dataclass(frozen=True)
class Latency:
    decisions: int
    mean_ms: float
    p50_ms: float
    p99_ms: float
    max_ms: float


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
        decisions, float(ms.mean()), *(float(np.percentile(ms, q)) for q in (50, 99)), float(ms.max())
    )


def latency_on_dataset(
    model_dir: Path, data_dir: Path, split: str = "test", decisions: int = 500, threads: int = 1
) -> Latency:
    """Latency on up to 50 full-size frames of a dataset split, with the fixed instruction."""
    planner = LatentPlanner(model_dir, threads=threads)
    index = load_index(data_dir)
    images = [read_image(r.image, index.width_px) for r in index.split(split)[:50]]
    instruction = fill(builtin_templates("fixed")[0], "gauge")
    return measure_latency(planner, images, instruction, decisions)
