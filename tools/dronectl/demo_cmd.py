"""`dronectl demo`: take off in the simulated world, fly a few moves, save camera frames.

    dronectl demo                       # frames in runs/demo/
    dronectl demo --out /tmp/demo --seconds 10 --seed 3 --scene scenes/default.yaml

Prints the target's pixel offset (du, dv) from the image centre at each saved frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from drone_inspect_core.files import claimed_dir
from dronectl.options import CommandParser, seed_value


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(
        prog="dronectl demo", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--out",
        type=Path,
        help="frames folder, new or empty: frames never go over another's (default runs/demo/<time>)",
    )
    p.add_argument("--seconds", type=float, default=16.0, help="length of the scripted flight (default 16)")
    p.add_argument("--fps", type=float, default=2.0, help="frames saved per simulated second (default 2)")
    p.add_argument("--scene", type=Path, default=None, help="scene config YAML (default: built-in)")
    p.add_argument("--seed", type=seed_value, default=0, help="scene seed (default 0)")
    p.add_argument("--gui", action="store_true", help="open the PyBullet GUI (needs a display)")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    from sim_world.collection.demo import DemoConfig, DemoFrame, run_demo
    from sim_world.scene.config import DEFAULT_SCENE, SceneConfigError, load_scene_config
    from sim_world.world import WorldConfig

    def show(frame: DemoFrame) -> None:
        offset = frame.offset_px
        where = "out of view" if offset is None else f"du {offset[0]:+7.1f}  dv {offset[1]:+7.1f}"
        print(f"t {frame.time_s:6.2f} s  {frame.leg:<5}  target {where}  -> {frame.image}")

    out = args.out or Path("runs") / "demo" / time.strftime("%Y%m%d-%H%M%S")
    try:
        scene = load_scene_config(args.scene) if args.scene else DEFAULT_SCENE
        config = DemoConfig(
            out_dir=out,
            seconds=args.seconds,
            frames_per_s=args.fps,
            seed=args.seed,
            world=WorldConfig(scene=scene, gui=args.gui),
        )
    except (SceneConfigError, ValueError) as exc:
        print(f"dronectl demo: {exc}", file=sys.stderr)
        return 2
    with claimed_dir(out, "frames folder"):  # a demo that fails before its first frame leaves no folder
        result = run_demo(config, on_frame=show)
    print(f"{result.target_kind} target; {len(result.frames)} frames in {out}; landed: {result.landed}")
    return 0 if result.landed else 1
