"""`dronectl reproduce`: run the paper's experiments and write a Markdown report with figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from controller.training.config import PRESETS
from drone_inspect_core.parallel import add_ray_option
from dronectl.options import (
    CommandParser,
    add_distillation_options,
    add_width_option,
    at_least,
    distillation_overrides,
)


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl reproduce", description=__doc__)
    p.add_argument(
        "--data",
        type=Path,
        nargs="+",
        required=True,
        help="dataset folder written by `dronectl collect` (grounded: the training folders, several)",
    )
    p.add_argument("--out", type=Path, required=True, help="report folder (report.md, figures, runs/)")
    p.add_argument("--seeds", type=int, default=5, help="seeds per experiment (paper: 5)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu")
    p.add_argument(
        "--workers",
        type=at_least(1),
        default=1,
        help="training processes in parallel (or the local Ray's CPUs)",
    )
    add_ray_option(p)
    p.add_argument("--threads", type=at_least(1), default=2, help="torch threads shared by all workers")
    p.add_argument(
        "--experiments",
        choices=("all", "table2", "table3", "main", "grounded"),
        default="all",
        help="all (Tables 2 and 3), one table, main (varied instructions + cosine only), or grounded "
        "(the instruction chooses among several targets: the grounded preset trained on --data, "
        "evaluated on --test and --heldout-look)",
    )
    p.add_argument("--test", type=Path, nargs="+", default=[], help="grounded: test dataset folders")
    p.add_argument(
        "--heldout-look", type=Path, default=None, help="grounded: the held-out scene family's test folder"
    )
    p.add_argument("--epochs", type=at_least(1), default=None, help="override the preset's epochs")
    p.add_argument(
        "--shift-init-std",
        type=float,
        default=None,
        help="grounded: override the preset's spread of g_X, g_Z at initialisation (a recipe under test)",
    )
    add_distillation_options(p, "grounded: ")
    add_width_option(p, "grounded: (a recipe under test) ")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.seeds < 1 or args.workers < 1:
        raise SystemExit("dronectl reproduce: --seeds and --workers must be >= 1")
    if args.experiments != "grounded" and (len(args.data) != 1 or args.test or args.heldout_look):
        raise SystemExit(
            "dronectl reproduce: the paper's experiments take one --data folder and no --test/--heldout-look"
        )
    if args.experiments == "grounded" and not (args.test or args.heldout_look):
        raise SystemExit("dronectl reproduce: --experiments grounded needs --test and/or --heldout-look")
    recipe = distillation_overrides(args)
    if args.shift_init_std is not None:
        recipe = {"shift_init_std": args.shift_init_std, **recipe}
    model = {} if args.width is None else {"base_width": args.width}
    if (recipe or model) and args.experiments != "grounded":
        options = [*("--" + k.replace("_", "-") for k in recipe), *(["--width"] if model else [])]
        raise SystemExit(f"dronectl reproduce: {', '.join(options)}: for --experiments grounded only")
    if args.threads < 1:
        raise SystemExit(f"dronectl reproduce: --threads must be >= 1, got {args.threads}")
    from drone_inspect_core.dataset import load_manifest

    for folder in [*args.data, *args.test, *([args.heldout_look] if args.heldout_look else [])]:
        load_manifest(folder, check_images=False)  # every dataset checked before any training starts
    from controller.evaluation.reproduce import ReproduceTaskError, reproduce
    from controller.evaluation.reproduce_grounded import reproduce_grounded
    from drone_inspect_core.parallel import RayUnavailableError

    try:
        if args.experiments == "grounded":
            path = reproduce_grounded(
                args.data,
                args.test,
                args.heldout_look,
                args.out,
                seeds=args.seeds,
                workers=args.workers,
                epochs=args.epochs,
                total_threads=args.threads,
                ray=args.ray,
                model_overrides=model,
                train_overrides=recipe,
            )
            print(f"report: {path}")
            return 0
        path = reproduce(
            args.data[0],
            args.out,
            seeds=args.seeds,
            preset=args.preset,
            workers=args.workers,
            experiments=args.experiments,
            epochs=args.epochs,
            total_threads=args.threads,
            ray=args.ray,
        )
    except RayUnavailableError as exc:
        print(f"dronectl reproduce: {exc}", file=sys.stderr)
        return 2
    except ReproduceTaskError as exc:
        print(f"dronectl reproduce: {exc}", file=sys.stderr)
        return 1
    print(f"report: {path}")
    return 0
