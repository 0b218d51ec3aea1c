"""Train the learned trim-colour reader (`perception.colour_model`; `dronectl train-colour`).

Samples: every target in view with a trim colour and a truth box, in the rows of collected datasets
that are not held out (`drone_inspect_core.dataset.is_held_out`: rendered rows of the test scene seeds,
flown rows of the test time blocks). Each image is used twice, lossless and as the simulated camera's
stream sends it at a JPEG quality drawn from `jpeg_quality` (`perception.evaluation.streamed`: 4:2:0
chroma, as most cameras' streams), and each time every box is jittered by `box_jitter` of its side per
edge (the detector's boxes are off by 4–6 % of a side), so the reader learns the trims as the loop
receives them. A seeded `val_fraction` of the images picks the best epoch (accuracy).

Test: the held-out rows of the same datasets, at their truth boxes, lossless and through the stream at
its quality, read by the trained network and by the rule reader (`perception.attributes`), per kind,
written to `metrics.json`. Augmentation in training: a brightness gain on the colour channels (not a
hue change: the hue is the label) and horizontal flips.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from drone_inspect_core.dataset import DatasetError, is_held_out, load_manifest, read_image_rgb, row_targets
from drone_inspect_core.files import claimed_dir, write_json_atomic
from perception.attributes import read_colour
from perception.colour_model import ColourNet, ColourNetConfig, ColourReader, save_checkpoint, target_crop
from perception.evaluation.streamed import STREAM_JPEG_QUALITY, as_streamed

log = logging.getLogger(__name__)

ENCODINGS = ("lossless", "stream")


@dataclass(frozen=True)
class TrainColourConfig:
    """Everything one training run needs; built by the command line."""

    data_dirs: tuple[Path, ...]
    out_dir: Path
    epochs: int = 12
    batch_size: int = 128
    lr: float = 3e-3
    weight_decay: float = 1e-4
    val_fraction: float = 0.1
    seed: int = 0
    box_jitter: float = 0.05
    jpeg_quality: tuple[int, int] = (60, 95)
    """The stream's JPEG quality is drawn from this range (inclusive) per training image."""
    brightness: float = 0.2
    """Colour channels scaled by a gain in [1 − b, 1 + b] per crop."""
    net: ColourNetConfig = field(default_factory=ColourNetConfig)

    def __post_init__(self) -> None:
        if not self.data_dirs:
            raise ValueError("at least one dataset folder is needed")
        if self.epochs < 1 or self.batch_size < 1:
            raise ValueError(f"epochs and batch_size must be >= 1, got {self.epochs}, {self.batch_size}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if not 0.0 <= self.box_jitter <= 0.3 or not 0.0 <= self.brightness < 1.0:
            raise ValueError(
                f"box_jitter must be in [0, 0.3], brightness in [0, 1), "
                f"got {self.box_jitter}, {self.brightness}"
            )
        lo, hi = self.jpeg_quality
        if not 1 <= lo <= hi <= 100:
            raise ValueError(f"jpeg_quality must be 1 <= lo <= hi <= 100, got {self.jpeg_quality}")


@dataclass
class ColourSamples:
    """Crops and labels, aligned by index: crops (N, S, S, 4) uint8 (RGB and the in-frame channel,
    ×255), kind and colour indices into the network's config, and the image each came from."""

    crops: np.ndarray
    kinds: np.ndarray
    colours: np.ndarray
    images: np.ndarray

    def __len__(self) -> int:
        return len(self.colours)

    def subset(self, mask: np.ndarray) -> ColourSamples:
        return ColourSamples(self.crops[mask], self.kinds[mask], self.colours[mask], self.images[mask])

    @staticmethod
    def concat(parts: Sequence[ColourSamples]) -> ColourSamples:
        return ColourSamples(
            *(np.concatenate([getattr(p, f) for p in parts]) for f in ("crops", "kinds", "colours", "images"))
        )


def labelled_targets(
    row: dict[str, Any], net: ColourNetConfig
) -> list[tuple[tuple[float, float, float, float], int, int]]:
    """(truth box, kind index, colour index) of each target in view in `row` that the network can learn:
    its kind and colour among the network's, a box recorded."""
    out = []
    for target in row_targets(row):
        box, kind, colour = target.get("bbox_px"), target.get("kind"), target.get("attribute")
        if target.get("in_view") and box is not None and kind in net.kinds and colour in net.colours:
            out.append((tuple(float(v) for v in box), net.kinds.index(kind), net.colours.index(colour)))
    return out  # type: ignore[return-value]


def crop_u8(image: np.ndarray, box: Sequence[float], kind: str, net: ColourNetConfig) -> np.ndarray:
    """`target_crop` as stored for training: uint8, ×255."""
    return np.round(target_crop(image, tuple(box), kind, net) * 255.0).astype(np.uint8)  # type: ignore[arg-type]


def load_samples(config: TrainColourConfig) -> tuple[ColourSamples, list[tuple[np.ndarray, list[Any]]]]:
    """The training crops, and the held-out (image, targets) pairs for the test."""
    rng = np.random.default_rng(config.seed)
    net = config.net
    parts: list[ColourSamples] = []
    held_out: list[tuple[np.ndarray, list[Any]]] = []
    image_id = 0
    for folder in config.data_dirs:
        rows, meta = load_manifest(folder)
        for row in tqdm(rows, desc=f"crops {Path(folder).name}", unit="image", leave=False):
            if row["split"] == "empty":
                continue
            targets = labelled_targets(row, net)
            if not targets:
                continue
            image = read_image_rgb(Path(folder) / row["image"])
            if is_held_out(row, meta):
                held_out.append((image, targets))
                continue
            lo, hi = config.jpeg_quality
            for picture in (image, as_streamed(image, int(rng.integers(lo, hi + 1)))):
                crops, kinds, colours = [], [], []
                for box, kind, colour in targets:
                    x0, y0, x1, y1 = box
                    w, h = x1 - x0, y1 - y0
                    jitter = rng.normal(0.0, config.box_jitter, 4) * np.array([w, h, w, h])
                    crops.append(crop_u8(picture, np.asarray(box) + jitter, net.kinds[kind], net))
                    kinds.append(kind)
                    colours.append(colour)
                parts.append(
                    ColourSamples(
                        np.stack(crops), np.array(kinds), np.array(colours), np.full(len(kinds), image_id)
                    )
                )
            image_id += 1
    if not parts:
        raise DatasetError(
            f"no target in view with a trim colour of {list(net.colours)} and a kind of {list(net.kinds)} in "
            f"the training rows of {', '.join(str(d) for d in config.data_dirs)}"
        )
    return ColourSamples.concat(parts), held_out


def _tensors(samples: ColourSamples) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    crops = torch.from_numpy(samples.crops).permute(0, 3, 1, 2).float().div_(255.0)
    return crops, torch.from_numpy(samples.kinds).long(), torch.from_numpy(samples.colours).long()


def train_on_samples(
    config: TrainColourConfig, train: ColourSamples, val: ColourSamples
) -> tuple[ColourNet, list[dict[str, float]], int]:
    """Train a fresh network on `train`; the weights of the epoch best on `val` (accuracy, then loss),
    the per-epoch history and that epoch's index."""
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    model = ColourNet(config.net)
    x, k, y = _tensors(train)
    vx, vk, vy = _tensors(val)
    steps = config.epochs * math.ceil(len(y) / config.batch_size)
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=config.lr, total_steps=steps)
    history: list[dict[str, float]] = []
    best: tuple[float, float] | None = None
    best_state, best_epoch = copy.deepcopy(model.state_dict()), 0
    for epoch in range(config.epochs):
        model.train()
        order = torch.randperm(len(y), generator=gen)
        total = 0.0
        for start in range(0, len(y), config.batch_size):
            idx = order[start : start + config.batch_size]
            batch = x[idx].clone()
            gain = 1.0 + config.brightness * (2.0 * torch.rand(len(idx), 1, 1, 1, generator=gen) - 1.0)
            batch[:, :3] = (batch[:, :3] * gain).clamp_(0.0, 1.0)
            if torch.rand(1, generator=gen).item() < 0.5:
                batch = batch.flip(3)
            loss = F.cross_entropy(model(batch, k[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        model.eval()
        with torch.no_grad():
            logits = model(vx, vk) if len(vy) else torch.zeros(0, len(config.net.colours))
            val_loss = float(F.cross_entropy(logits, vy)) if len(vy) else 0.0
            val_acc = float((logits.argmax(1) == vy).float().mean()) if len(vy) else 0.0
        history.append(
            {"epoch": epoch, "train_loss": total / len(y), "val_loss": val_loss, "val_accuracy": val_acc}
        )
        log.info(
            "epoch %d: train loss %.4f, val loss %.4f, val accuracy %.4f",
            epoch,
            total / len(y),
            val_loss,
            val_acc,
        )
        if best is None or (val_acc, -val_loss) > best:
            best, best_epoch = (val_acc, -val_loss), epoch
            best_state = copy.deepcopy(model.state_dict())
    model.load_state_dict(best_state)
    return model.eval(), history, best_epoch


def held_out_reads(model: ColourNet, held_out: Sequence[tuple[np.ndarray, list[Any]]]) -> dict[str, Any]:
    """Right reads on the held-out targets at their truth boxes, by the network and by the rule reader,
    lossless and through the stream (`STREAM_JPEG_QUALITY`), per kind."""
    reader = ColourReader(model)
    net = model.config
    right: Counter[tuple[str, str, str]] = Counter()
    seen: Counter[tuple[str, str]] = Counter()
    for image, targets in held_out:
        for encoding, picture in zip(
            ENCODINGS, (image, as_streamed(image, STREAM_JPEG_QUALITY)), strict=True
        ):
            asked = [(box, net.kinds[kind]) for box, kind, _ in targets]
            learned = reader.read_all(picture, asked)
            for (box, kind_name), read, (_, _, colour) in zip(asked, learned, targets, strict=True):
                truth = net.colours[colour]
                rule = read_colour(picture, box, kind_name)
                seen[encoding, kind_name] += 1
                right["learned", encoding, kind_name] += read is not None and read.name == truth
                right["rules", encoding, kind_name] += rule is not None and rule.name == truth
    out: dict[str, Any] = {"targets": sum(seen.values()) // len(ENCODINGS)}
    for reader_name in ("learned", "rules"):
        out[reader_name] = {
            encoding: {
                "right": sum(right[reader_name, encoding, kind] for kind in net.kinds),
                "of": sum(seen[encoding, kind] for kind in net.kinds),
                "by_kind": {
                    kind: [right[reader_name, encoding, kind], seen[encoding, kind]] for kind in net.kinds
                },
            }
            for encoding in ENCODINGS
        }
    return out


@dataclass(frozen=True)
class ColourTrainResult:
    best_epoch: int
    val_accuracy: float
    samples: int
    seconds: float
    test: dict[str, Any]


def train_colour(config: TrainColourConfig) -> ColourTrainResult:
    """Load the datasets, train, test, and write the run folder (refused when it holds a run already)."""
    start = time.time()
    with claimed_dir(config.out_dir, "run folder"):
        samples, held_out = load_samples(config)
        rng = np.random.default_rng(config.seed + 1)
        images = np.unique(samples.images)
        val_images = rng.choice(images, size=max(1, round(config.val_fraction * len(images))), replace=False)
        in_val = np.isin(samples.images, val_images)
        train, val = samples.subset(~in_val), samples.subset(in_val)
        log.info(
            "%d training crops, %d validation crops, %d held-out images", len(train), len(val), len(held_out)
        )
        model, history, best_epoch = train_on_samples(config, train, val)
        test = held_out_reads(model, held_out)
        seconds = time.time() - start
        info = {
            "trained_on": [str(d) for d in config.data_dirs],
            "epochs": config.epochs,
            "best_epoch": best_epoch,
            "seed": config.seed,
            "box_jitter": config.box_jitter,
            "jpeg_quality": list(config.jpeg_quality),
            "samples": {"train": len(train), "val": len(val)},
            "seconds": round(seconds, 1),
        }
        save_checkpoint(config.out_dir, model, {"training": info})
        write_json_atomic(
            config.out_dir / "metrics.json",
            {"history": history, "best_epoch": best_epoch, "test": test, "training": info},
        )
    return ColourTrainResult(best_epoch, history[best_epoch]["val_accuracy"], len(samples), seconds, test)
