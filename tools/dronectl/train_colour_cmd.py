"""`dronectl train-colour`: train the learned trim-colour reader on collected dataset folders.

    dronectl train-colour --data data/wide data/wide2 data/twins data/multi --out runs/colour

Each image is learned lossless and as the simulated camera's stream sends it (4:2:0 JPEG), around its
targets' truth boxes jittered as the detector's are; the datasets' held-out rows are read at the end by
the new reader and by the rule reader, and both are written to the run folder's `metrics.json`. A
detector run folder with a `colour/` folder holding such a run reads colours with it
(`ImageDetector.load`); the shipped one is `perception/assets/colour/` (perception/assets/README.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from drone_inspect_core.dataset import DatasetError
from drone_inspect_core.files import OutputDirError
from dronectl.options import CommandParser, at_least, seed_value
from perception.colour_model import ColourNetConfig
from perception.errors import PerceptionError
from perception.training.colour import TrainColourConfig, train_colour


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl train-colour", description=__doc__)
    p.add_argument(
        "--data", type=Path, nargs="+", required=True, help="dataset folders written by `dronectl collect`"
    )
    p.add_argument(
        "--out", type=Path, required=True, help="new run folder for model.safetensors, config.json, metrics"
    )
    p.add_argument("--epochs", type=at_least(1), default=12)
    p.add_argument("--batch-size", type=at_least(1), default=128)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--crop", type=int, default=40, help="crop size in pixels (16-128)")
    p.add_argument("--seed", type=seed_value, default=0)
    p.add_argument("--threads", type=at_least(1), default=2, help="torch threads")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        config = TrainColourConfig(
            data_dirs=tuple(args.data),
            out_dir=args.out,
            epochs=args.epochs,
            batch_size=args.batch_size,
            lr=args.lr,
            seed=args.seed,
            net=ColourNetConfig(crop_px=args.crop),
        )
        result = train_colour(config)
    except (ValueError, DatasetError, OutputDirError, PerceptionError) as exc:
        print(f"dronectl train-colour: {exc}", file=sys.stderr)
        return 1
    print(
        f"best epoch {result.best_epoch} (validation accuracy {result.val_accuracy:.4f}), "
        f"{result.samples} crops, {result.seconds:.0f} s"
    )
    test = result.test
    for reader in ("learned", "rules"):
        parts = [f"{enc} {v['right']}/{v['of']}" for enc, v in test[reader].items()]
        print(f"held-out targets read right, {reader}: " + ", ".join(parts))
    print(json.dumps(test, indent=2))
    return 0
