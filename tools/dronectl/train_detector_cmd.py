"""`dronectl train-detector`: train the image-based target detector on a collected dataset folder.

    dronectl train-detector --data data/det --out runs/det
    dronectl train-detector --data data/my-flange --extra data/rehearsal --init perception/assets/detector \
        --out runs/det-flange --epochs 8

With --init the run fine-tunes that checkpoint; a kind the datasets hold that it does not know is added
(its head grows a class; the kinds it knows keep their weights), and the kind's words (from the dataset,
where the collection recorded them) are saved with the new checkpoint, so missions and the planner know
it. Give datasets of the kinds it already knows too (--extra), or the fine-tune may forget them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from drone_inspect_core.dataset import DatasetError
from drone_inspect_core.vocabulary import VocabularyError
from dronectl.options import CommandParser, at_least, seed_value
from perception.detector_model import DetectorConfig
from perception.errors import PerceptionError
from perception.training.train import TrainDetectorConfig, train_detector


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl train-detector", description=__doc__)
    p.add_argument("--data", type=Path, required=True, help="dataset folder written by `dronectl collect`")
    p.add_argument(
        "--extra",
        type=Path,
        action="append",
        default=[],
        help="another dataset folder whose rows (all splits) are added to training; rows of "
        "--data's test scene seeds are dropped (repeatable)",
    )
    p.add_argument(
        "--out", type=Path, required=True, help="run folder for model.safetensors, config.json, metrics"
    )
    p.add_argument(
        "--init",
        type=Path,
        default=None,
        help="fine-tune this detector checkpoint (perception/assets/detector: the shipped one); kinds the "
        "data holds that it lacks are added",
    )
    p.add_argument("--epochs", type=at_least(1), default=30)
    p.add_argument("--batch-size", type=at_least(1), default=32)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--crop", type=int, default=128, help="training crop size in pixels (multiple of 32)")
    p.add_argument(
        "--val-fraction", type=float, default=0.1, help="share of training rows held out for validation"
    )
    p.add_argument("--seed", type=seed_value, default=0)
    p.add_argument("--threads", type=at_least(1), default=2, help="torch threads")
    p.add_argument(
        "--input-size",
        type=int,
        default=None,
        help="network input size (multiple of 32; default 224, or --init's)",
    )
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.threads < 1:
        raise ValueError(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    config = TrainDetectorConfig(
        data_dir=args.data,
        extra_dirs=tuple(args.extra),
        out_dir=args.out,
        init_dir=args.init,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        crop_px=args.crop,
        val_fraction=args.val_fraction,
        seed=args.seed,
        detector=None if args.input_size is None else DetectorConfig(input_size=args.input_size),
    )
    try:
        result = train_detector(config)
    except (DatasetError, PerceptionError, VocabularyError) as exc:
        print(f"dronectl train-detector: {exc}", file=sys.stderr)
        return 1
    print(f"best epoch {result.best_epoch} (val loss {result.best_val_loss:.4f}) in {result.seconds:.0f} s")
    print(f"weights: {args.out / 'model.safetensors'}; kinds: {', '.join(result.kinds)}")
    if result.added:
        print(f"added kinds: {', '.join(result.added)}")
    if result.test is not None:
        print("test:", result.test.summary())
        print(json.dumps(result.test.as_dict(), indent=2))
    return 0
