"""Train the image detector on a dataset's truth boxes (`dronectl train-detector`).

Training rows: `goal` and `train` (training scene seeds), plus `empty` rows of
training scene seeds as pure negatives; a seeded 80/20 split of them gives the
validation set that picks the best epoch (lowest validation loss). The held-out
`test` split and the `empty` rows of test scene seeds are scored once at the end
and written to `metrics.json` beside the weights.

Losses (CenterNet): penalty-reduced focal loss on the kind heatmaps, L1 on the
sub-cell centre offset and on the log edge distances over the 3×3 cells around
each centre (so a peak one cell off still places the centre well).
Augmentation: horizontal flips, brightness / contrast / colour gains, pixel noise.
"""

from __future__ import annotations

import copy
import json
import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from tqdm import tqdm

from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.dataset import DatasetError, load_manifest
from drone_inspect_core.files import claimed_dir, write_json_atomic
from perception.detector_model import STRIDE, CentreNet, DetectorConfig
from perception.evaluation.evaluate import DetectorMetrics, evaluate_detections, evaluate_on_dataset
from perception.image_detector import ImageDetector, normalise, save_checkpoint
from perception.training.data import (
    DetectorSamples,
    Targets,
    load_samples,
    make_targets,
    scaled_row,
    split_train_val,
)
from perception.training.kinds import StartingPoint, starting_point

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainDetectorConfig:
    """Everything one training run needs; built by the command line."""

    data_dir: Path
    out_dir: Path
    extra_dirs: tuple[Path, ...] = ()
    """More datasets whose rows (all splits) join training, minus rows of `data_dir`'s test scene seeds."""
    init_dir: Path | None = None
    """Start from this run's weights (fine-tuning; kinds the data holds that it lacks are added:
    `perception.training.kinds`)."""
    epochs: int = 30
    batch_size: int = 32
    crop_px: int = 128
    """Training crop size (multiple of 32); validation and test run on whole frames."""
    lr: float = 2e-3
    weight_decay: float = 1e-4
    val_fraction: float = 0.1
    seed: int = 0
    detector: DetectorConfig | None = None
    """The architecture (None: the default, or with `init_dir` the checkpoint's; its kinds are extended by
    the data's)."""

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch_size < 1:
            raise ValueError(f"epochs and batch_size must be >= 1, got {self.epochs}, {self.batch_size}")
        if self.crop_px % 32 or not 64 <= self.crop_px <= (self.detector or DetectorConfig()).input_size:
            raise ValueError(f"crop_px must be a multiple of 32 in [64, input_size], got {self.crop_px}")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in [0, 1), got {self.val_fraction}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"lr must be > 0, got {self.lr}")


@dataclass(frozen=True)
class TrainDetectorResult:
    best_epoch: int
    best_val_loss: float
    val: DetectorMetrics | None
    test: DetectorMetrics | None
    seconds: float
    kinds: tuple[str, ...] = ()
    added: tuple[str, ...] = ()


def focal_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """CenterNet's penalty-reduced focal loss, summed and divided by the number of centres."""
    pos = target.eq(1.0)
    log_p = F.logsigmoid(logits)
    log_not_p = F.logsigmoid(-logits)
    p = torch.sigmoid(logits)
    pos_loss = ((1.0 - p) ** 2 * log_p)[pos].sum()
    neg_loss = ((1.0 - target) ** 4 * p**2 * log_not_p)[~pos].sum()
    return -(pos_loss + neg_loss) / pos.sum().clamp(min=1)


def detector_loss(
    out: torch.Tensor, targets: Targets, num_kinds: int
) -> tuple[torch.Tensor, dict[str, float]]:
    """Total loss and its parts for a batch of raw head outputs (B, K + 6, G, G)."""
    heat = focal_loss(out[:, :num_kinds], targets.heatmap)
    mask = targets.reg_mask.unsqueeze(1)  # (B, 1, G, G)
    n = mask.sum().clamp(min=1)
    offset = ((out[:, num_kinds : num_kinds + 2] - targets.offset).abs() * mask).sum() / (2 * n)
    edges = ((out[:, num_kinds + 2 :] - targets.edges).abs() * mask).sum() / (4 * n)
    total = heat + offset + 0.5 * edges
    return total, {"heat": heat.item(), "offset": offset.item(), "edges": edges.item()}


def random_crops(
    samples: DetectorSamples, idx: torch.Tensor, crop: int, gen: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Crops of `crop` pixels, most around the target, some anywhere; truth moved and clipped to them.

    The network is fully convolutional, so it trains on crops (about 3× cheaper
    than whole frames) and runs on whole frames. A crop whose edge cuts the target
    keeps it as a positive while its centre is inside the crop and makes it a
    negative once the centre is outside, which teaches the detector to stay silent
    about a target it cannot centre on instead of boxing its visible part.
    """
    images = samples.images[idx]
    b, _, height, width = images.shape
    centres = samples.centres_px[idx].clone()
    bboxes = samples.bboxes_px[idx].clone()
    kinds = samples.kinds[idx].clone()
    around = (torch.rand(b, generator=gen) < 0.75) & (kinds >= 0)
    # Around the target: its centre lands uniformly in the crop, give or take a margin of 8 px.
    jitter = (torch.rand(b, 2, generator=gen) * (crop + 16) - 8).round()
    near = (centres - jitter).round()
    anywhere = (torch.rand(b, 2, generator=gen) * torch.tensor([width - crop + 1, height - crop + 1])).floor()
    origin = torch.where(around[:, None], near, anywhere)
    origin[:, 0] = origin[:, 0].clamp(0, width - crop)
    origin[:, 1] = origin[:, 1].clamp(0, height - crop)
    ox, oy = origin[:, 0].long(), origin[:, 1].long()
    out = torch.stack([images[i, :, oy[i] : oy[i] + crop, ox[i] : ox[i] + crop] for i in range(b)])
    centres -= origin
    bboxes -= origin.repeat(1, 2)
    bboxes = bboxes.clamp(0.0, float(crop))
    inside = (centres >= 0).all(1) & (centres < crop).all(1)
    visible = (bboxes[:, 2] > bboxes[:, 0]) & (bboxes[:, 3] > bboxes[:, 1])
    kinds[~(inside & visible)] = -1
    return out, centres, bboxes, kinds


def augment(
    images: torch.Tensor, centres: torch.Tensor, bboxes: torch.Tensor, gen: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Random flips and photometric changes; returns normalised float images and adjusted truth."""
    b, _, _, size = images.shape
    x = images.float() / 255.0
    flip = torch.rand(b, generator=gen) < 0.5
    x[flip] = x[flip].flip(-1)
    centres, bboxes = centres.clone(), bboxes.clone()
    centres[flip, 0] = size - centres[flip, 0]
    bboxes[flip] = torch.stack(
        [size - bboxes[flip, 2], bboxes[flip, 1], size - bboxes[flip, 0], bboxes[flip, 3]], 1
    )
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    contrast = 0.75 + 0.5 * torch.rand(b, 1, 1, 1, generator=gen)
    brightness = 0.8 + 0.4 * torch.rand(b, 1, 1, 1, generator=gen)
    gains = 0.9 + 0.2 * torch.rand(b, 3, 1, 1, generator=gen)
    x = ((x - mean) * contrast + mean) * brightness * gains
    x = x + torch.randn(x.shape, generator=gen) * (torch.rand(b, 1, 1, 1, generator=gen) * 4.0 / 255.0)
    x = x.clamp(0.0, 1.0)
    return normalise((x * 255.0).round().to(torch.uint8)), centres, bboxes


def _batches(n: int, batch_size: int, gen: torch.Generator | None) -> list[torch.Tensor]:
    order = torch.randperm(n, generator=gen) if gen is not None else torch.arange(n)
    return list(order.split(batch_size))


@torch.no_grad()
def validation_loss(model: CentreNet, samples: DetectorSamples, batch_size: int) -> float:
    model.eval()
    cfg = model.config
    total, count = 0.0, 0
    for idx in _batches(len(samples), batch_size, None):
        targets = make_targets(
            samples.centres_px[idx], samples.bboxes_px[idx], samples.kinds[idx], len(cfg.kinds), cfg.grid_size
        )
        loss, _ = detector_loss(model(normalise(samples.images[idx])), targets, len(cfg.kinds))
        total += float(loss) * len(idx)
        count += len(idx)
    return total / max(count, 1)


def score(model: CentreNet, samples: DetectorSamples, batch_size: int = 64) -> DetectorMetrics:
    """Accuracy of a (copied, fused) model on samples, in their input-size pixels."""
    detector = ImageDetector(copy.deepcopy(model))
    images = samples.images.permute(0, 2, 3, 1).numpy()
    detections = []
    for start in range(0, len(samples), batch_size):
        detections += detector.detect_batch(list(images[start : start + batch_size]))
    size = model.config.input_size
    rows = [scaled_row(r, *samples.scale) for r in samples.rows]
    return evaluate_detections(rows, detections, size, size, default_epsilon_px(size))


def load_training_data(
    config: TrainDetectorConfig,
) -> tuple[DetectorSamples, DetectorSamples, dict[str, Any]]:
    """(train, val, dataset.json of `data_dir`): its goal/train rows, empty rows of its training scenes
    and every row of the extra datasets except those of `data_dir`'s test scenes."""
    cfg = config.detector
    assert cfg is not None  # resolved by `train_detector`
    _, meta = load_manifest(config.data_dir, check_images=False)
    for extra in config.extra_dirs:  # every folder checked before minutes of loading
        load_manifest(extra, check_images=False)
    train_seeds = set(meta.get("train_scene_seeds") or [])
    test_seeds = set(meta.get("test_scene_seeds") or [])
    pool = load_samples(config.data_dir, ("goal", "train"), cfg.kinds, cfg.input_size)
    if train_seeds:
        try:
            negatives = load_samples(config.data_dir, ("empty",), cfg.kinds, cfg.input_size, train_seeds)
            pool = _concat(pool, negatives)
        except DatasetError:
            log.info("no empty rows of training scene seeds: negatives come from the other rows only")
    for extra in config.extra_dirs:
        splits = ("goal", "train", "test", "empty")
        more = load_samples(extra, splits, cfg.kinds, cfg.input_size, exclude_seeds=test_seeds)
        if more.scale != pool.scale:
            raise DatasetError(f"{extra}: camera size differs from {config.data_dir}")
        pool = _concat(pool, more)
    train_idx, val_idx = split_train_val(len(pool), config.val_fraction, config.seed)
    train, val = pool.subset(train_idx), pool.subset(val_idx)
    log.info(
        "training on %d images (%d positives), validating on %d",
        len(train),
        int(train.positive.sum()),
        len(val),
    )
    return train, val, meta


def train_one_epoch(
    model: CentreNet,
    train: DetectorSamples,
    optimiser: torch.optim.Optimizer,
    schedule: torch.optim.lr_scheduler.LRScheduler,
    config: TrainDetectorConfig,
    gen: torch.Generator,
    desc: str,
) -> dict[str, float]:
    """One pass over shuffled training crops; returns the mean loss parts."""
    model.train()
    kinds_n = len(model.config.kinds)
    parts_sum: dict[str, float] = {}
    batches = _batches(len(train), config.batch_size, gen)
    for idx in tqdm(batches, desc=desc, leave=False):
        crops, centres, bboxes, kinds = random_crops(train, idx, config.crop_px, gen)
        x, centres, bboxes = augment(crops, centres, bboxes, gen)
        targets = make_targets(centres, bboxes, kinds, kinds_n, config.crop_px // STRIDE)
        loss, parts = detector_loss(model(x.contiguous(memory_format=torch.channels_last)), targets, kinds_n)
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
        schedule.step()
        for key, value in parts.items():
            parts_sum[key] = parts_sum.get(key, 0.0) + value / len(batches)
    return parts_sum


def train_detector(config: TrainDetectorConfig) -> TrainDetectorResult:
    """Train; save the best epoch by validation loss as soon as it is reached; score it on the test split."""
    start = time.monotonic()
    torch.manual_seed(config.seed)
    # The starting checkpoint, the datasets and the kinds' words are checked before anything trains.
    begin = starting_point([config.data_dir, *config.extra_dirs], config.init_dir, config.detector)
    model = begin.model
    config = replace(config, detector=model.config)
    if config.crop_px > model.config.input_size:
        raise ValueError(f"crop_px {config.crop_px} exceeds the input size {model.config.input_size}")
    if config.init_dir is not None:
        log.info("starting from the weights in %s", config.init_dir)
        if begin.missing:
            log.warning(
                "no training row shows %s: the fine-tune may forget them (add a dataset of them: --extra)",
                ", ".join(begin.missing),
            )
    # The run folder must be new or empty, and a run that fails before writing leaves none behind.
    with claimed_dir(config.out_dir, "run folder"):
        train, val, meta = load_training_data(config)
        return _fit(config, begin, train, val, meta, start)


def _fit(
    config: TrainDetectorConfig,
    begin: StartingPoint,
    train: DetectorSamples,
    val: DetectorSamples,
    meta: dict[str, Any],
    start: float,
) -> TrainDetectorResult:
    """`train_detector` once the data is loaded and the run folder claimed."""
    model = begin.model.to(memory_format=torch.channels_last)
    optimiser = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps = config.epochs * math.ceil(len(train) / config.batch_size)
    schedule = torch.optim.lr_scheduler.OneCycleLR(
        optimiser, max_lr=config.lr, total_steps=steps, pct_start=0.1
    )
    gen = torch.Generator().manual_seed(config.seed)
    training: dict[str, Any] = {
        "data_dir": str(config.data_dir),
        "extra_dirs": [str(d) for d in config.extra_dirs],
        "init_dir": None if config.init_dir is None else str(config.init_dir),
        "dataset_seed": meta.get("seed"),
        "epochs": config.epochs,
        "seed": config.seed,
        "batch_size": config.batch_size,
        "crop_px": config.crop_px,
        "lr": config.lr,
        "train_images": len(train),
        "val_images": len(val),
        "added_kinds": list(begin.added),
    }
    kinds = {"kinds": begin.own_kinds}
    best_loss, best_epoch, best_state = float("inf"), -1, None
    with (config.out_dir / "train_log.jsonl").open("w", encoding="utf-8") as train_log:
        for epoch in range(1, config.epochs + 1):
            parts = train_one_epoch(
                model, train, optimiser, schedule, config, gen, f"epoch {epoch}/{config.epochs}"
            )
            val_loss = validation_loss(model, val, 64) if len(val) else parts["heat"]
            record = {"epoch": epoch, "val_loss": val_loss, **{f"train_{k}": v for k, v in parts.items()}}
            train_log.write(json.dumps(record) + "\n")
            train_log.flush()
            log.info(
                "epoch %d: %s", epoch, " ".join(f"{k} {v:.4f}" for k, v in record.items() if k != "epoch")
            )
            if val_loss < best_loss:
                best_loss, best_epoch = val_loss, epoch
                best_state = copy.deepcopy(model.state_dict())
                best = {**kinds, "training": {**training, "best_epoch": epoch}}
                save_checkpoint(config.out_dir, model, best)
    assert best_state is not None
    model.load_state_dict(best_state)
    model.eval()
    val_metrics = score(model, val) if len(val) else None
    test_metrics = _score_test(model, config.data_dir)
    seconds = time.monotonic() - start
    training.update(best_epoch=best_epoch, seconds=round(seconds, 1))
    save_checkpoint(config.out_dir, model, {**kinds, "training": training})
    metrics = {
        "best_val_loss": best_loss,
        "val": val_metrics.as_dict() if val_metrics else None,
        "test": test_metrics.as_dict() if test_metrics else None,
    }
    write_json_atomic(config.out_dir / "metrics.json", metrics)
    if val_metrics:
        log.info("val: %s", val_metrics.summary())
    if test_metrics:
        log.info("test: %s", test_metrics.summary())
    return TrainDetectorResult(
        best_epoch, best_loss, val_metrics, test_metrics, seconds, model.config.kinds, begin.added
    )


def _score_test(model: CentreNet, data_dir: Path) -> DetectorMetrics | None:
    try:
        return evaluate_on_dataset(ImageDetector(copy.deepcopy(model)), data_dir)
    except DatasetError as exc:
        log.warning("no test metrics: %s", exc)
        return None


def _concat(a: DetectorSamples, b: DetectorSamples) -> DetectorSamples:
    return DetectorSamples(
        torch.cat([a.images, b.images]),
        torch.cat([a.centres_px, b.centres_px]),
        torch.cat([a.bboxes_px, b.bboxes_px]),
        torch.cat([a.kinds, b.kinds]),
        a.rows + b.rows,
        a.scale,
    )
