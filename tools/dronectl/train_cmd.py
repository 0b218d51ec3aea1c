"""`dronectl train`: train the latent dynamics planner on a collected dataset folder."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from controller.planning.latent.config import DISTANCES, FUSIONS, POOLINGS
from controller.training.config import PRESET_NOTES, PRESETS, AugmentConfig, LossWeights, run_configs
from dronectl.options import (
    CommandParser,
    add_distillation_options,
    add_width_option,
    at_least,
    distillation_overrides,
    seed_value,
)


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl train", description=__doc__)
    p.add_argument(
        "--data",
        type=Path,
        nargs="+",
        required=True,
        help="dataset folder(s) written by `dronectl collect` (several: trained on together)",
    )
    p.add_argument(
        "--out", type=Path, required=True, help="run folder for the checkpoint, metrics and curves"
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="cpu",
        help="; ".join(f"{k}: {v}" for k, v in PRESET_NOTES.items()).replace("%", "%%"),
    )
    p.add_argument(
        "--init",
        type=Path,
        default=None,
        help="fine-tune this planner checkpoint (its model; the data's new kinds' words join its tokenizer); "
        "the own-target preset starts from the shipped one",
    )
    p.add_argument("--distance", choices=DISTANCES, default=None, help="D: cosine (default), euclidean, both")
    p.add_argument("--instructions", choices=("fixed", "varied"), default=None, help="default varied")
    p.add_argument("--seed", type=seed_value, default=None)
    p.add_argument(
        "--loss-weights", type=LossWeights.parse, default=None, metavar="dir=1,rank=1,cons=1,reg=1"
    )
    p.add_argument(
        "--epochs", type=at_least(1), default=None, help="default: the preset's (paper 50, cpu 30)"
    )
    p.add_argument("--threads", type=at_least(1), default=None, help="torch threads (default 2)")
    p.add_argument("--image-size", type=int, default=None, help="override the preset's input size")
    add_width_option(p)
    p.add_argument(
        "--coord-channels", choices=("on", "off"), default=None, help="override (u, v) input planes"
    )
    p.add_argument(
        "--lr-schedule", choices=("constant", "cosine"), default=None, help="override the preset's"
    )
    p.add_argument("--lr", type=float, default=None, help="Adam learning rate (default 3e-4)")
    p.add_argument("--temperature", type=float, default=None, help="ranking τ (paper 1.0, cpu 0.1)")
    p.add_argument("--pooling", choices=POOLINGS, default=None, help="E_img head (paper: gap)")
    p.add_argument("--fusion", choices=FUSIONS, default=None, help="state fusion (paper: linear)")
    p.add_argument("--batch-size", type=at_least(1), default=None, help="default 64")
    p.add_argument(
        "--translate",
        type=float,
        default=None,
        help="label-exact shift, max fraction of the image per axis (0 = off, the paper's set)",
    )
    p.add_argument("--hflip", choices=("on", "off"), default=None, help="label-exact horizontal flip")
    p.add_argument("--scale", type=float, default=None, help="label-exact zoom range (0 = off)")
    p.add_argument("--hue", type=float, default=None, help="hue jitter, fraction of a full turn")
    p.add_argument("--saturation", type=float, default=None, help="saturation jitter")
    p.add_argument(
        "--balance-kinds", choices=("on", "off"), default=None, help="equal sampling mass per target kind"
    )
    p.add_argument("--no-augment", action="store_true", help="turn augmentation off")
    p.add_argument("--epsilon-px", type=float, default=None, help="ε in dataset pixels (default 10 at 224)")
    p.add_argument("--brightness", type=float, default=None, help="brightness jitter")
    p.add_argument("--contrast", type=float, default=None, help="contrast jitter")
    p.add_argument(
        "--relight", type=float, default=None, help="light falling off across the image, log-gain (0 = off)"
    )
    p.add_argument("--gamma", type=float, default=None, help="tone-curve jitter (0 = off)")
    p.add_argument("--tint", type=float, default=None, help="per-channel gain jitter (0 = off)")
    p.add_argument(
        "--named-fraction",
        type=float,
        default=None,
        help="described targets: share of samples asking for the image's named target (default 0.5)",
    )
    p.add_argument(
        "--channels-last", choices=("on", "off"), default=None, help="channels-last memory order (speed)"
    )
    p.add_argument(
        "--ema",
        type=float,
        default=None,
        metavar="DECAY",
        help="save a moving average of the weights (0 = off)",
    )
    p.add_argument(
        "--device",
        default="cpu",
        help="where the model trains: cpu (default), cuda, cuda:N, or auto (a GPU if torch sees one)",
    )
    p.add_argument(
        "--shift-init-std",
        type=float,
        default=None,
        help="spread of the global action shifts g_X, g_Z at initialisation (default 0.01)",
    )
    add_distillation_options(p, "grounded preset: ")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _given(**values: object) -> dict[str, object]:
    """The options given on the command line (None: not given, the preset's value stays)."""
    return {k: v for k, v in values.items() if v is not None}


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    on = {None: None, "on": True, "off": False}  # the on/off switches; None keeps the preset's
    model_over = _given(
        image_size=args.image_size,
        base_width=args.width,
        coord_channels=on[args.coord_channels],
        pooling=args.pooling,
        fusion=args.fusion,
    )
    train_over: dict[str, object] = _given(
        lr_schedule=args.lr_schedule,
        learning_rate=args.lr,
        temperature=args.temperature,
        batch_size=args.batch_size,
        named_fraction=args.named_fraction,
        channels_last=on[args.channels_last],
        ema_decay=args.ema,
        balance_kinds=on[args.balance_kinds],
        epsilon_px=args.epsilon_px,
        shift_init_std=args.shift_init_std,
        **distillation_overrides(args),
    )
    aug_over = _given(
        translate=args.translate,
        hflip=on[args.hflip],
        scale=args.scale,
        hue=args.hue,
        saturation=args.saturation,
        brightness=args.brightness,
        contrast=args.contrast,
        relight=args.relight,
        gamma=args.gamma,
        tint=args.tint,
    )
    if aug_over:
        train_over["augment"] = replace(PRESETS[args.preset].train.augment, **aug_over)
    if args.no_augment:
        train_over["augment"] = AugmentConfig(enabled=False)
    run = run_configs(
        args.preset,
        distance=args.distance,
        instructions=args.instructions,
        seed=args.seed,
        weights=args.loss_weights,
        epochs=args.epochs,
        threads=args.threads,
        model_overrides=model_over,
        train_overrides=train_over,
    )
    init = args.init or run.init
    if init is not None and model_over:
        raise SystemExit(
            f"dronectl train: {', '.join(sorted(model_over))}: a fine-tune keeps its checkpoint's model "
            f"({init}); leave the model options out"
        )
    from controller.training.train import resolve_device, train  # torch only once arguments are valid

    try:
        resolve_device(args.device)
    except ValueError as exc:
        raise SystemExit(f"dronectl train: {exc}") from None
    result = train(
        list(args.data),
        args.out,
        run.model,
        run.train,
        progress=not args.quiet,
        device=args.device,
        init_dir=init,
    )
    print(
        json.dumps(
            {
                "out": str(result.out_dir),
                "best_val_accuracy": round(result.best_val_accuracy, 4),
                "best_epoch": result.best_epoch,
                "seconds": round(result.seconds, 1),
                "images_per_s": round(result.images_per_s, 1),
            }
        )
    )
    return 0
