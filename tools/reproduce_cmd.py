"""`dronectl reproduce`: run the paper's experiments and write a Markdown report with figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from controller.planning.latent.config import PRESETS
from core.parallel import add_ray_option


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dronectl reproduce", description=__doc__)
    p.add_argument("--data", type=Path, required=True, help="dataset folder written by `dronectl collect`")
    p.add_argument("--out", type=Path, required=True, help="report folder (report.md, figures, runs/)")
    p.add_argument("--seeds", type=int, default=5, help="seeds per experiment (paper: 5)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu")
    p.add_argument(
        "--workers", type=int, default=1, help="training processes in parallel (or the local Ray's CPUs)"
    )
    add_ray_option(p)
    p.add_argument("--threads", type=int, default=2, help="torch threads shared by all workers")
    p.add_argument(
        "--experiments",
        choices=("all", "table2", "table3", "main"),
        default="all",
        help="all (Tables 2 and 3), one table, or main (varied instructions + cosine only)",
    )
    p.add_argument("--epochs", type=int, default=None, help="override the preset's epochs")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.seeds < 1 or args.workers < 1:
        raise SystemExit("dronectl reproduce: --seeds and --workers must be >= 1")
    from controller.planning.latent.reproduce import ReproduceTaskError, reproduce
    from core.parallel import RayUnavailableError

    try:
        path = reproduce(
            args.data,
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
