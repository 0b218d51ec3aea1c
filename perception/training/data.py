"""Detector data: dataset images in memory, their truth boxes, and the training targets.

Reads the dataset folder written by `dronectl collect` (through
`drone_inspect_core.dataset.load_manifest`) into one uint8 tensor. A row is a positive when
the target's centre is in the image (`in_view`) and part of its face is visible
(`bbox_px`); every other row (target out of view, split `empty`) is a negative
that teaches the detector to say nothing. Images of another size are resized to
the detector's input size and their pixel truth scaled with them.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from drone_inspect_core.dataset import DatasetError, load_manifest, read_rgb
from perception.detector_model import EDGE_SCALE_PX, STRIDE

log = logging.getLogger(__name__)


@dataclass
class DetectorSamples:
    """Images and truth, aligned by index. Pixel values are in the detector's input size."""

    images: torch.Tensor  # (N, 3, S, S) uint8
    centres_px: torch.Tensor  # (N, 2) float32
    bboxes_px: torch.Tensor  # (N, 4) float32 (u0, v0, u1, v1); zeros for rows without a box
    kinds: torch.Tensor  # (N,) int64, index into the detector's kinds; -1 for negatives
    rows: list[dict[str, Any]]
    scale: tuple[float, float] = (1.0, 1.0)  # input-size pixels per camera pixel (u, v)

    def __len__(self) -> int:
        return int(self.images.shape[0])

    @property
    def positive(self) -> torch.Tensor:
        return self.kinds >= 0

    def subset(self, index: Sequence[int] | torch.Tensor) -> DetectorSamples:
        idx = torch.as_tensor(index, dtype=torch.long)
        return DetectorSamples(
            self.images[idx],
            self.centres_px[idx],
            self.bboxes_px[idx],
            self.kinds[idx],
            [self.rows[i] for i in idx.tolist()],
            self.scale,
        )


def is_positive(row: dict[str, Any]) -> bool:
    """The detector should report this row's target: centre in the image and a visible box."""
    return bool(row["in_view"]) and row["bbox_px"] is not None and row["split"] != "empty"


def load_samples(
    directory: str | Path,
    splits: Sequence[str],
    kinds: Sequence[str],
    input_size: int,
    scene_seeds: set[int] | None = None,
    limit: int | None = None,
    exclude_seeds: set[int] | None = None,
) -> DetectorSamples:
    """Load the rows of `splits`: only those of `scene_seeds` if given, none of `exclude_seeds`,
    at most `limit`."""
    root = Path(directory)
    rows, meta = load_manifest(root)
    chosen = [
        r
        for r in rows
        if r["split"] in splits
        and (scene_seeds is None or r.get("scene_seed") in scene_seeds)
        and (exclude_seeds is None or r.get("scene_seed") not in exclude_seeds)
    ]
    if limit is not None:
        chosen = chosen[:limit]
    if not chosen:
        raise DatasetError(f"{root}: no rows in splits {list(splits)}")
    width, height = int(meta["camera"]["width"]), int(meta["camera"]["height"])
    sx, sy = input_size / width, input_size / height
    n = len(chosen)
    images = torch.empty((n, 3, input_size, input_size), dtype=torch.uint8)
    centres = torch.zeros((n, 2), dtype=torch.float32)
    bboxes = torch.zeros((n, 4), dtype=torch.float32)
    kind_index = torch.full((n,), -1, dtype=torch.long)
    for i, row in enumerate(tqdm(chosen, desc=f"loading {root.name} {'/'.join(splits)}", leave=False)):
        images[i] = torch.from_numpy(read_rgb(root / row["image"], input_size)).permute(2, 0, 1)
        centres[i] = torch.tensor([row["centre_px"][0] * sx, row["centre_px"][1] * sy])
        if is_positive(row):
            if row["target_kind"] not in kinds:
                raise DatasetError(
                    f"{root}: row {row['id']}: target_kind {row['target_kind']!r} not in {list(kinds)}"
                )
            u0, v0, u1, v1 = row["bbox_px"]
            bboxes[i] = torch.tensor([u0 * sx, v0 * sy, u1 * sx, v1 * sy])
            kind_index[i] = kinds.index(row["target_kind"])
    log.info("%s: %d rows (%d positives) from %s", root, n, int((kind_index >= 0).sum()), list(splits))
    several = sum(1 for row in chosen if len(row.get("targets") or ()) > 1)
    if several:
        log.warning(
            "%s: %d rows show several targets; the detector trains on each row's named target only, so the "
            "others are taught as background (collect one target per scene for the detector)",
            root,
            several,
        )
    return DetectorSamples(images, centres, bboxes, kind_index, chosen, (sx, sy))


def scaled_row(row: dict[str, Any], sx: float, sy: float) -> dict[str, Any]:
    """A manifest row with its pixel truth scaled to the detector's input size (a no-op at 224 px)."""
    if sx == 1.0 and sy == 1.0:
        return row
    scaled = dict(row)
    scaled["centre_px"] = [row["centre_px"][0] * sx, row["centre_px"][1] * sy]
    scaled["offset_px"] = [row["offset_px"][0] * sx, row["offset_px"][1] * sy]
    if row["bbox_px"] is not None:
        u0, v0, u1, v1 = row["bbox_px"]
        scaled["bbox_px"] = [u0 * sx, v0 * sy, u1 * sx, v1 * sy]
    return scaled


@dataclass
class Targets:
    """Training targets on the stride-4 grid."""

    heatmap: torch.Tensor  # (B, K, G, G) in [0, 1], exactly 1 at each target's centre cell
    reg_mask: torch.Tensor  # (B, G, G) bool: the 3×3 cells around each centre cell
    offset: torch.Tensor  # (B, 2, G, G) centre position in cell units relative to each cell
    edges: torch.Tensor  # (B, 4, G, G) log(distance to bbox edges / EDGE_SCALE_PX)


def make_targets(
    centres_px: torch.Tensor, bboxes_px: torch.Tensor, kinds: torch.Tensor, num_kinds: int, grid: int
) -> Targets:
    """Gaussian centre heatmaps (σ grows with the box) and regression targets for a batch."""
    b = centres_px.shape[0]
    pos = kinds >= 0
    cx, cy = centres_px[:, 0] / STRIDE, centres_px[:, 1] / STRIDE  # continuous cell coordinates
    box_w = (bboxes_px[:, 2] - bboxes_px[:, 0]).clamp(min=1.0)
    box_h = (bboxes_px[:, 3] - bboxes_px[:, 1]).clamp(min=1.0)
    sigma = (torch.minimum(box_w, box_h) / (STRIDE * 6.0)).clamp(0.75, 3.0)
    cells = torch.arange(grid, dtype=torch.float32) + 0.5
    gx = torch.exp(-((cells[None, :] - cx[:, None]) ** 2) / (2 * sigma[:, None] ** 2))  # (B, G)
    gy = torch.exp(-((cells[None, :] - cy[:, None]) ** 2) / (2 * sigma[:, None] ** 2))
    gauss = gy[:, :, None] * gx[:, None, :]  # (B, G, G)
    ix = cx.floor().long().clamp(0, grid - 1)
    iy = cy.floor().long().clamp(0, grid - 1)
    batch = torch.arange(b)
    gauss[batch, iy, ix] = 1.0
    heatmap = torch.zeros((b, num_kinds, grid, grid))
    heatmap[batch[pos], kinds[pos]] = gauss[pos]

    grid_x = torch.arange(grid).view(1, 1, grid)
    grid_y = torch.arange(grid).view(1, grid, 1)
    near = ((grid_x - ix.view(b, 1, 1)).abs() <= 1) & ((grid_y - iy.view(b, 1, 1)).abs() <= 1)
    reg_mask = near & pos.view(b, 1, 1)
    offset = torch.stack(
        [
            (cx.view(b, 1, 1) - grid_x.float()).expand(b, grid, grid),
            (cy.view(b, 1, 1) - grid_y.float()).expand(b, grid, grid),
        ],
        dim=1,
    )  # (B, 2, G, G)
    distances = torch.stack(
        [
            centres_px[:, 0] - bboxes_px[:, 0],
            centres_px[:, 1] - bboxes_px[:, 1],
            bboxes_px[:, 2] - centres_px[:, 0],
            bboxes_px[:, 3] - centres_px[:, 1],
        ],
        dim=1,
    ).clamp(min=0.5)
    edges = torch.log(distances / EDGE_SCALE_PX).view(b, 4, 1, 1).expand(b, 4, grid, grid)
    return Targets(heatmap, reg_mask, offset, edges)


def split_train_val(n: int, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A seeded random split of n indices into (train, val)."""
    order = np.random.default_rng(seed).permutation(n)
    n_val = math.ceil(n * val_fraction) if n > 1 else 0
    return np.sort(order[n_val:]), np.sort(order[:n_val])
