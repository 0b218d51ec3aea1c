"""Reading a collected dataset folder (docs/architecture.md) into labelled in-memory tensors.

The folder stores truth, not labels: each row's label is derived here from its
`offset_px` with `controller.planning.actions.label_from_offset` and ε (10 px at 224 px,
scaled with the camera width, unless given). Images are decoded once and resized
to the model's input size; the whole paper-sized dataset fits in memory at the
sizes used here (1,700 × 3 × 112² bytes ≈ 64 MB).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from controller.planning.actions import label_from_offset
from controller.planning.latent.errors import TrainingDataError
from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.dataset import DatasetError as ManifestError
from drone_inspect_core.dataset import load_manifest, read_rgb, row_targets

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TargetRef:
    """One target of an image, as a planner's training sample can ask for it."""

    kind: str
    attribute: str | None
    """Its trim colour's name (drone_inspect_core.vocabulary), None where the manifest does not say."""
    offset_px: tuple[float, float]
    in_view: bool


@dataclass(frozen=True)
class Row:
    """One manifest row, reduced to what the planner needs."""

    id: str
    image: Path
    split: str
    target_kind: str
    offset_px: tuple[float, float]
    scene_seed: int | None
    """The rendered scene's seed; None for a flown capture."""
    in_view: bool
    targets: tuple[TargetRef, ...] = ()
    """Every target of the scene, the named one first (one entry for a single-target dataset)."""


@dataclass(frozen=True)
class DatasetIndex:
    root: Path
    meta: dict[str, Any]
    rows: tuple[Row, ...]
    width_px: int
    height_px: int

    def split(self, name: str) -> list[Row]:
        return [r for r in self.rows if r.split == name]

    def default_epsilon_px(self) -> float:
        return default_epsilon_px(self.width_px)


@dataclass
class ImageSet:
    """Images (N, 3, S, S) uint8, labels (N,) action indices, offsets (N, 2) px, kinds, ids, splits,
    and every image's targets (the named one first; labels and offsets are the named target's)."""

    images: torch.Tensor
    labels: torch.Tensor
    offsets: torch.Tensor
    kinds: list[str]
    ids: list[str]
    splits: list[str]
    targets: list[tuple[TargetRef, ...]] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.images.shape[0])

    def subset(self, index: Sequence[int] | torch.Tensor) -> ImageSet:
        idx = torch.as_tensor(index, dtype=torch.long)
        return ImageSet(
            self.images[idx],
            self.labels[idx],
            self.offsets[idx],
            [self.kinds[i] for i in idx.tolist()],
            [self.ids[i] for i in idx.tolist()],
            [self.splits[i] for i in idx.tolist()],
            [self.targets[i] for i in idx.tolist()] if self.targets else [],
        )


def load_index(root: Path) -> DatasetIndex:
    """Read a dataset folder with `drone_inspect_core.dataset.load_manifest` (the format's one reader)."""
    root = Path(root)
    try:
        raw_rows, meta = load_manifest(root)
    except ManifestError as exc:
        raise TrainingDataError(str(exc)) from exc
    try:
        width, height = int(meta["camera"]["width"]), int(meta["camera"]["height"])
    except (KeyError, TypeError, ValueError) as exc:
        raise TrainingDataError(f"{root / 'dataset.json'}: camera width/height missing or malformed") from exc
    rows = tuple(_row(raw, root) for raw in raw_rows)
    if not rows:
        raise TrainingDataError(f"{root / 'manifest.jsonl'} holds no rows")
    return DatasetIndex(root, meta, rows, width, height)


def _target_refs(raw: dict[str, Any]) -> tuple[TargetRef, ...]:
    """Every target of a manifest row (`drone_inspect_core.dataset.row_targets`, which also reads rows from
    before
    several-target scenes), the named one first."""
    listed = row_targets(raw)
    named = int(raw.get("named", 0))
    refs = [
        TargetRef(str(t["kind"]), t.get("attribute"), (float(t["offset_px"][0]), float(t["offset_px"][1])),
                  bool(t["in_view"]))
        for t in listed
    ]  # fmt: skip
    return (refs[named], *refs[:named], *refs[named + 1 :])


def _row(raw: dict[str, Any], root: Path) -> Row:
    offset = raw["offset_px"]
    return Row(
        id=str(raw["id"]),
        image=root / str(raw["image"]),
        split=str(raw["split"]),
        target_kind=str(raw["target_kind"]),
        offset_px=(float(offset[0]), float(offset[1])),
        scene_seed=int(raw["scene_seed"]) if "scene_seed" in raw else None,
        in_view=bool(raw["in_view"]),
        targets=_target_refs(raw),
    )


def read_image(path: Path, size: int) -> np.ndarray:
    """Decode a dataset PNG as RGB uint8 resized to size × size (`drone_inspect_core.dataset.read_rgb`)."""
    try:
        return read_rgb(path, size)
    except ManifestError as exc:
        raise TrainingDataError(str(exc)) from exc


def load_images(
    rows: Sequence[Row],
    size: int,
    epsilon_px: float,
    desc: str = "images",
    progress: bool = False,
    in_view_only: bool = True,
) -> ImageSet:
    """Decode `rows` into an `ImageSet` with labels derived at ε = `epsilon_px` (dataset pixels).

    `in_view_only=False` keeps rows whose named target is out of view (the `empty` split, for
    judging a model's "not in view"); their labels are meaningless and must not be scored.
    """
    usable = [r for r in rows if (r.in_view or not in_view_only) and np.isfinite(r.offset_px).all()]
    if len(usable) < len(rows):
        log.info("%s: skipped %d rows with no target in view", desc, len(rows) - len(usable))
    if not usable:
        raise TrainingDataError(f"no usable {desc} rows (target in view, offset known)")
    images = np.empty((len(usable), size, size, 3), dtype=np.uint8)
    for i, row in enumerate(tqdm(usable, desc=f"loading {desc}", leave=False, disable=not progress)):
        images[i] = read_image(row.image, size)
    labels = [label_from_offset(r.offset_px[0], r.offset_px[1], epsilon_px).index for r in usable]
    return ImageSet(
        images=torch.from_numpy(images).permute(0, 3, 1, 2).contiguous(),  # (N, 3, S, S)
        labels=torch.tensor(labels, dtype=torch.long),
        offsets=torch.tensor([r.offset_px for r in usable], dtype=torch.float32),
        kinds=[r.target_kind for r in usable],
        ids=[r.id for r in usable],
        splits=[r.split for r in usable],
        targets=[r.targets for r in usable],
    )


def split_train_val(n: int, val_fraction: float, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A seeded random 80/20 (by default) split of range(n) into train and validation indices."""
    perm = torch.randperm(n, generator=torch.Generator().manual_seed(seed))
    n_val = max(1, round(n * val_fraction))
    return perm[n_val:], perm[:n_val]


def to_float(images_u8: torch.Tensor) -> torch.Tensor:
    """(B, 3, S, S) uint8 → float32 in [0, 1]."""
    return images_u8.to(torch.float32).div_(255.0)
