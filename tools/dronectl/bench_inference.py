"""`dronectl bench inference`: the planner and the detector on torch and on ONNX Runtime, side by side.

On the same frames of a dataset folder (`dronectl collect`): each model's largest output difference
between the backends and whether their decisions agree, then latency per decision (planner: resize,
image encoding, 9 candidates) and per frame (detector: network and decoding), p50 / p99, the backends
timed in alternating rounds, wall time and the thread's CPU time (the wall time less what other
processes took of the core). Needs onnxruntime (`pip install -e '.[onnx]'`). The load average is
printed beside the figures: other work on the machine slows them.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

import torch

from controller.benchmarks.perception import compare_detector_backends
from controller.benchmarks.planner_latency import FIXED_INSTRUCTION, compare_backends, dataset_frames
from controller.planning.planners import DEFAULT_CHECKPOINT
from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, at_least, new_file
from perception.image_detector import SHIPPED_DIR


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl bench inference", description=__doc__)
    p.add_argument("--data", type=Path, required=True, help="dataset folder: its test frames are timed")
    p.add_argument("--model", type=Path, default=DEFAULT_CHECKPOINT, help="planner checkpoint folder")
    p.add_argument("--weights", type=Path, default=SHIPPED_DIR, help="detector run folder")
    p.add_argument("--decisions", type=at_least(1), default=1000, help="planner decisions timed per backend")
    p.add_argument(
        "--frames", type=at_least(0), default=1000, help="detector frames timed per backend (0: skip)"
    )
    p.add_argument("--threads", type=at_least(1), default=1, help="threads of either backend")
    p.add_argument("--json", type=new_file, default=None, help="also write the figures here")
    return p


def _lines(name: str, unit: str, result: dict[str, Any], difference: str, agree: str) -> list[str]:
    lines = [f"{name}: {result['images']} frames, max |onnx - torch| {result[difference]:.2e}, "
             f"same {agree}: {'yes' if result['same_' + agree] else 'NO'}"]  # fmt: skip
    for backend, t in result["latency"].items():
        lines.append(
            f"  {backend:>5}: p50 {t['p50_ms']:.2f} ms, p99 {t['p99_ms']:.2f} ms, "
            f"mean {t['mean_ms']:.2f} ms, max {t['max_ms']:.2f} ms over {t['calls']} {unit}; "
            f"CPU time p50 {t['cpu_p50_ms']:.2f} ms, p99 {t['cpu_p99_ms']:.2f} ms"
        )
    return lines


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    torch.set_num_threads(args.threads)
    frames = dataset_frames(args.data)
    results: dict[str, Any] = {"threads": args.threads, "cpu_count": os.cpu_count(),
                               "load_avg_start": list(os.getloadavg())}  # fmt: skip
    results["planner"] = compare_backends(args.model, frames, FIXED_INSTRUCTION, args.decisions, args.threads)
    results["load_avg_after_planner"] = list(os.getloadavg())
    lines = _lines("planner", "decisions", results["planner"], "max_abs_distance_difference", "actions")
    lines.append(f"  load average {results['load_avg_start'][0]:.2f} before, "
                 f"{results['load_avg_after_planner'][0]:.2f} after on {os.cpu_count()} CPUs")  # fmt: skip
    if args.frames > 0:
        results["detector"] = compare_detector_backends(args.weights, frames, args.frames, args.threads)
        results["load_avg_after_detector"] = list(os.getloadavg())
        lines += _lines("detector", "frames", results["detector"], "max_abs_head_difference", "kinds")
        lines.append(f"  load average {results['load_avg_after_detector'][0]:.2f} after")
    print("\n".join(lines))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, results, indent=2)
    return 0
