"""`train_detector` end to end on a tiny synthetic dataset in the real folder format."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from drone_inspect_core.dataset import DatasetError
from perception.detector_model import DetectorConfig
from perception.training.train import TrainDetectorConfig, train_detector
from perception.image_detector import ImageDetector

SIZE = 64
KINDS = ("gauge", "valve", "switchbox")


def write_synthetic_dataset(root: Path, counts: dict[str, int], seed: int = 0) -> Path:
    """Bright discs (gauge) and squares (switchbox) on a noisy wall, with grey decoys, as `dronectl collect`
    would lay them out: dataset.json, manifest.jsonl, images/*.png."""
    rng = np.random.default_rng(seed)
    (root / "images").mkdir(parents=True)
    rows = []
    for split, n in counts.items():
        for i in range(n):
            img = rng.normal(90, 12, (SIZE, SIZE, 3)).clip(0, 255).astype(np.uint8)
            cv2.rectangle(
                img, (int(rng.integers(0, 50)), int(rng.integers(0, 50))), (60, 60), (70, 70, 70), 2
            )
            kind = str(rng.choice(["gauge", "switchbox"]))
            u, v, r = float(rng.uniform(12, 52)), float(rng.uniform(12, 52)), float(rng.uniform(5, 9))
            if split != "empty":
                if kind == "gauge":
                    cv2.circle(img, (round(u), round(v)), round(r), (250, 250, 240), -1)
                else:
                    cv2.rectangle(
                        img, (round(u - r), round(v - r)), (round(u + r), round(v + r)), (240, 240, 250), -1
                    )
            image_id = f"{split}_{i:06d}"
            cv2.imwrite(str(root / "images" / f"{image_id}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            present = split != "empty"
            rows.append(
                {
                    "id": image_id,
                    "image": f"images/{image_id}.png",
                    "split": split,
                    "sector": "centre" if present else "none",
                    "scene_seed": 1 if split in ("goal", "train") else 2,
                    "target_kind": kind,
                    "centre_px": [u, v],
                    "offset_px": [u - SIZE / 2, v - SIZE / 2],
                    "bbox_px": [u - r, v - r, u + r, v + r] if present else None,
                    "in_view": present,
                    "fully_in_view": present,
                    "visible_fraction": 1.0 if present else 0.0,
                    "depth_m": 2.0,
                    "drone": {},
                    "offset_m": {},
                    "scene": {},
                }
            )
    (root / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    meta = {
        "generator_version": "test",
        "seed": seed,
        "camera": {"width": SIZE, "height": SIZE},
        "scene_config": {},
        "counts": counts,
        "train_scene_seeds": [1],
        "test_scene_seeds": [2],
    }
    (root / "dataset.json").write_text(json.dumps(meta))
    return root


@pytest.mark.slow
def test_trains_saves_and_scores_on_a_synthetic_dataset(tmp_path: Path) -> None:
    torch.set_num_threads(1)
    data = write_synthetic_dataset(tmp_path / "data", {"train": 160, "test": 40, "empty": 20})
    config = TrainDetectorConfig(
        data_dir=data,
        out_dir=tmp_path / "run",
        epochs=20,
        batch_size=16,
        crop_px=64,
        lr=5e-3,
        seed=3,
        detector=DetectorConfig(input_size=SIZE, widths=(8, 16, 16, 16, 16), neck_width=16, kinds=KINDS),
    )
    result = train_detector(config)
    run = tmp_path / "run"
    assert {p.name for p in run.iterdir()} >= {
        "model.safetensors",
        "config.json",
        "metrics.json",
        "train_log.jsonl",
    }
    log = [json.loads(line) for line in (run / "train_log.jsonl").read_text().splitlines()]
    assert len(log) == 20
    assert log[-1]["train_heat"] < 0.5 * log[0]["train_heat"]  # it learns
    assert 1 <= result.best_epoch <= 20
    metrics = json.loads((run / "metrics.json").read_text())["test"]
    assert metrics["n_fully_in_view"] == 40 and metrics["n_empty"] == 20
    assert metrics["recall_fully_in_view"] >= 0.8  # an easy task, a few epochs
    assert metrics["centre_error_median_px"] <= 2.0
    detector = ImageDetector.load(run)
    assert detector.config.input_size == SIZE


def test_missing_dataset_is_a_clear_error(tmp_path: Path) -> None:
    config = TrainDetectorConfig(data_dir=tmp_path / "nothing", out_dir=tmp_path / "run", epochs=1)
    with pytest.raises(DatasetError, match="nothing"):
        train_detector(config)


def test_config_checks() -> None:
    with pytest.raises(ValueError, match="crop_px"):
        TrainDetectorConfig(data_dir=Path("d"), out_dir=Path("o"), crop_px=100)
    with pytest.raises(ValueError, match="epochs"):
        TrainDetectorConfig(data_dir=Path("d"), out_dir=Path("o"), epochs=0)
