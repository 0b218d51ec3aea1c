"""`dronectl bench sim`: physics and camera real-time factors, render times, collection throughput."""

from __future__ import annotations

import argparse
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import controller.benchmarks.sim as bench
from controller.benchmarks.sim import TARGETS, SimBenchSettings, cpu_hogs, run_sim_bench
from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, at_least, new_file, seed_value
from sim_world.rendering.render_mode import RENDER_MODES


def _loads(figures: dict[str, Any]) -> str:
    return f"{figures['load_avg_1min_before']:.2f} before, {figures['load_avg_1min_after']:.2f} after"


def format_report(result: dict[str, Any]) -> str:
    """The human-readable report of `run_sim_bench`'s result."""

    def verdict(value: float, key: str) -> str:
        return f"target >= {TARGETS[key]:g}: " + ("meets" if value >= TARGETS[key] else "BELOW")

    m, cam, mode = result["machine"], result["physics_camera"], result["render_mode"]
    phys = result["physics_no_camera"]["real_time_factor"]
    inline = cam["real_time_factor"]
    parallel = result["physics_camera_render_workers"]
    rtf_workers = parallel["real_time_factor"]
    coll = result["collection_224"]
    camera = f"{cam['camera_px']} px camera @ {cam['camera_hz']:g} Hz"
    lines = [
        f"machine: {m['cpus']} CPUs, load average {m['load_avg_1min_before']:.2f} before, "
        f"{m['load_avg_1min_after']:.2f} after (other work on the machine slows every number)",
        f"physics, no camera:                 {phys:6.1f}x real time ({verdict(phys, 'physics_rtf')}); "
        f"by CPU time {result['physics_no_camera']['cpu_real_time_factor']:.1f}x",
        f"physics + {camera}, single (inline): {inline:6.2f}x real time ({verdict(inline, 'camera_rtf')}); "
        f"by CPU time {cam['cpu_real_time_factor']:.2f}x; load {_loads(cam)}",
        f"physics + {camera}, {parallel['workers']} render workers: {rtf_workers:6.2f}x real time "
        f"({verdict(rtf_workers, 'camera_rtf')}); load {_loads(parallel)}",
        f"render mode: {mode['mode']} ({mode['reason']}"
        + (f"; {m['cpu_hogs']} CPU hog(s) running" if m.get("cpu_hogs") else "")
        + f"); faster in the full flight: {'workers' if rtf_workers > inline else 'single'}",
        "render per frame (ms)   p50 no-seg  p99 no-seg   p50 seg   p99 seg   CPU p50 no-seg",
    ]
    for size, row in result["render_ms"].items():
        lines.append(
            f"  {size:>4} px            {row['p50_ms_no_seg']:9.2f}  {row['p99_ms_no_seg']:10.2f}"
            f"  {row['p50_ms_seg']:8.2f}  {row['p99_ms_seg']:8.2f}  {row['cpu_p50_ms_no_seg']:14.2f}"
        )
    picked = mode["full_flight"]
    which = "picked" if picked["picked_the_faster"] else "NOT picked"
    lines.append(
        f"auto picked {picked['mode']}: {picked['real_time_factor']:.2f}x real time in the full flight; "
        f"the faster there: {picked['faster_mode']} ({which})"
    )
    peer = result.get("peer")
    if peer is not None and "real_time_factor" in peer:
        ratio = peer["ours_over_peer"]
        lines.append(
            f"peer (PyFlyt QuadX, 224 px camera @ 30 fps, hovering): {peer['real_time_factor']:.2f}x real "
            f"time (CPU {peer['cpu_real_time_factor']:.2f}x; load {peer['load_avg_1min']:.2f}); this world "
            f"in the picked mode: {ratio:.2f}x the peer's ({verdict(ratio, 'over_peer')})"
        )
    elif peer is not None:
        lines.append(f"peer: not measured: {peer['error']}")
    lines.append(
        f"collection at 224 px: {coll['images_per_s']:.1f} images/s ({coll['images']:.0f} images, "
        f"{coll['workers']:.0f} workers; {verdict(coll['images_per_s'], 'collect_images_per_s')}); "
        f"{coll['images_per_cpu_s']:.1f} images per CPU second"
    )
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """Entry point of `dronectl bench sim` (called by tools/dronectl/bench_cmd.py)."""
    parser = CommandParser(
        prog="dronectl bench sim",
        description=bench.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--json", type=new_file, default=None, help="also write the numbers to this JSON file"
    )
    parser.add_argument("--seed", type=seed_value, default=0, help="scene seed (default 0)")
    parser.add_argument(
        "--collect-images", type=at_least(1), default=400, help="images for the throughput run"
    )
    parser.add_argument("--workers", type=at_least(1), default=os.cpu_count() or 1, help="collection workers")
    parser.add_argument(
        "--render-mode",
        choices=RENDER_MODES,
        default="auto",
        help="render mode to choose: auto calibrates both here (the bench measures both anyway)",
    )
    parser.add_argument(
        "--cpu-hogs",
        type=int,
        default=0,
        help="busy-looping processes to run meanwhile (a measurement under load)",
    )
    parser.add_argument(
        "--peer-python",
        type=Path,
        help="an interpreter with PyFlyt (the optional extra [peer]; it pins numpy < 2, so usually a venv "
        "of its own): also measure PyFlyt's QuadX with its 224 px camera at 30 fps, and the ratio",
    )
    args = parser.parse_args(argv)
    settings = replace(
        SimBenchSettings(),
        seed=args.seed,
        collect_images=args.collect_images,
        collect_workers=args.workers,
        render_mode=args.render_mode,
        peer_python=args.peer_python,
    )
    with cpu_hogs(args.cpu_hogs):
        result = run_sim_bench(settings)
    result["machine"]["cpu_hogs"] = args.cpu_hogs
    print(format_report(result))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, result, indent=2)
        print(f"wrote {args.json}")
    return 0
