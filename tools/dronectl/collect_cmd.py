"""`dronectl collect`: render the paper's goal / sector / test / empty dataset in the simulated world.

    dronectl collect --out data/sim --seed 0
    dronectl collect --out data/small --seed 1 --n-goal 40 --n-per-sector 60 --n-test 120 --size 128
    dronectl collect --out data/multi --seed 2 --targets 2-4 --twins

With --targets, scenes hold several targets; the protocol (goal images, eight sectors,
test, empty) is taken relative to the named one, and every row lists all targets' truth.

Writes DIR/images/*.png, DIR/manifest.jsonl (truth per image) and DIR/dataset.json
(camera, scene config, seeds); see docs/architecture.md.

With --vehicle (sim-mavlink, px4-sitl or a MAVLink URL) the protocol is flown instead, through the
Vehicle interface: `dronectl collect --vehicle sim-mavlink --help` (docs/own-target.md).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from drone_inspect_core.parallel import add_ray_option


def target_count(text: str) -> tuple[int, int]:
    """`--targets`: a count `N` or a range `LO-HI` (checked against the scene config's limits later)."""
    parts = text.split("-")
    try:
        numbers = [int(part) for part in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or LO-HI, got {text!r}") from None
    if len(numbers) not in (1, 2):
        raise argparse.ArgumentTypeError(f"expected N or LO-HI, got {text!r}")
    return numbers[0], numbers[-1]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dronectl collect", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--out", type=Path, required=True, help="dataset folder to create (not an existing dataset)"
    )
    p.add_argument("--seed", type=int, required=True, help="seed of the whole dataset (scenes, poses, noise)")
    p.add_argument("--scene", type=Path, default=None, help="scene config YAML (default: built-in scenes)")
    p.add_argument(
        "--targets",
        type=target_count,
        default=None,
        metavar="N|LO-HI",
        help="targets per scene, 1..4, a number or a range (default: the scene config's target.count)",
    )
    p.add_argument(
        "--twins",
        action="store_true",
        help="one other target shares the named target's kind, in another trim colour (needs --targets >= 2)",
    )
    p.add_argument("--n-goal", type=int, default=100, help="goal images, target centred (default 100)")
    p.add_argument("--n-per-sector", type=int, default=200, help="images in each of 8 sectors (default 200)")
    p.add_argument("--n-test", type=int, default=400, help="test images, unseen scenes (default 400)")
    p.add_argument("--n-empty", type=int, default=100, help="images without the target in view (default 100)")
    p.add_argument("--size", type=int, default=224, help="square image size in pixels (default 224)")
    p.add_argument("--epsilon-px", type=float, default=None, help="ε in pixels (default 10 at 224, scaled)")
    p.add_argument("--images-per-scene", type=int, default=5, help="images per scene (default 5)")
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="processes, or the local Ray's CPUs (default: all CPUs)",
    )
    add_ray_option(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str]) -> int:
    if any(arg == "--vehicle" or arg.startswith("--vehicle=") for arg in argv):
        from dronectl.collect_flown_cmd import (
            main as collect_flown_main,
        )  # flown through the Vehicle interface

        return collect_flown_main(argv)
    args = build_parser().parse_args(argv)
    from drone_inspect_core.dataset import DatasetError
    from drone_inspect_core.parallel import RayUnavailableError
    from sim_world.collection.collect import CollectConfig, CollectionTaskError, collect
    from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config, with_targets

    try:
        scene = load_scene_config(args.scene) if args.scene else DEFAULT_SCENE
        if args.targets is not None or args.twins:
            scene = with_targets(scene, count=args.targets, twins=True if args.twins else None)
        if args.twins and scene.target.count[1] < 2:
            raise ValueError("--twins needs scenes of 2 or more targets (--targets 2 or more)")
        config = CollectConfig(
            out_dir=args.out,
            seed=args.seed,
            scene=scene,
            scene_file=str(args.scene) if args.scene else None,
            n_goal=args.n_goal,
            n_per_sector=args.n_per_sector,
            n_test=args.n_test,
            n_empty=args.n_empty,
            size_px=args.size,
            epsilon_px=args.epsilon_px,
            workers=args.workers,
            images_per_scene=args.images_per_scene,
        )
    except (SceneConfigError, ValueError) as exc:  # a bad scene file or option value
        print(f"dronectl collect: {exc}", file=sys.stderr)
        return 2
    try:
        result = collect(config, progress=not args.no_progress, ray=args.ray)
    except (DatasetError, RayUnavailableError) as exc:  # e.g. the folder already holds a dataset
        print(f"dronectl collect: {exc}", file=sys.stderr)
        return 2
    except CollectionTaskError as exc:
        print(f"dronectl collect: {exc}", file=sys.stderr)
        return 1
    counts = ", ".join(f"{split} {n}" for split, n in result.counts.items())
    print(f"wrote {sum(result.counts.values())} images ({counts}) to {result.out_dir}")
    print(f"{result.seconds:.1f} s, {result.images_per_s:.1f} images/s")
    return 0
