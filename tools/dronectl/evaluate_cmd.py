"""`dronectl evaluate`: rank-1, per-axis accuracy and confusion matrix of a trained planner."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from controller.planning.actions import ALL_ACTIONS
from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, at_least, new_file, say_error, seed_value

if TYPE_CHECKING:
    from controller.evaluation.evaluate import EvalResult
    from controller.evaluation.with_detector import WithDetectorResult


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="dronectl evaluate", description=__doc__)
    p.add_argument("--model", type=Path, required=True, help="checkpoint folder written by `dronectl train`")
    p.add_argument("--data", type=Path, required=True, help="dataset folder")
    p.add_argument(
        "--instructions",
        default="train",
        help="train (training-style), heldout (never-seen paraphrases and synonyms) or a text FILE: "
        "one instruction per line ({target} filled with the target's name), or `kind: phrase` lines "
        "(each test image gets a phrase of its named target's kind), or an operator-words YAML file "
        "(templates, words per kind and colour; docs/operator_words.yaml)",
    )
    p.add_argument(
        "--as-flown",
        action="store_true",
        help="also score the same instructions as flown: each understood by the loop's parser and heard "
        "by the planner in its trained words (refused or misread instructions count as failures)",
    )
    p.add_argument(
        "--with-detector",
        action="store_true",
        help="also score the planner as the centring loop shows it each image: the image detector takes "
        "the asked target (its kind; among twins, the trim colour it reads), the other targets of that "
        "kind painted over, the planner asked in its trained words",
    )
    p.add_argument(
        "--detector",
        type=Path,
        default=None,
        help="the image detector's checkpoint for --with-detector (default: the shipped one)",
    )
    p.add_argument(
        "--through-stream",
        action="store_true",
        help="with --with-detector: each image first through the simulated vehicle's MJPEG stream (4:2:0 "
        "JPEG, decoded as the stream camera decodes it), as a flight through sim-mavlink or SITL sees it",
    )
    p.add_argument(
        "--split", default="test", choices=("test", "train", "goal"), help="dataset split to score"
    )
    p.add_argument("--seed", type=seed_value, default=0, help="seed of the image/instruction pairing")
    p.add_argument("--epsilon-px", type=float, default=None, help="ε in dataset pixels (default 10 at 224)")
    p.add_argument(
        "--latency",
        type=at_least(0),
        default=0,
        metavar="N",
        help="also time N planner decisions on the test images",
    )
    p.add_argument("--threads", type=at_least(1), default=1, help="threads for the latency measurement")
    p.add_argument(
        "--backend",
        default="auto",
        choices=("torch", "onnx", "auto"),
        help="planner backend for the latency measurement (auto: onnx when onnxruntime is installed)",
    )
    p.add_argument(
        "--mirror-tta",
        action="store_true",
        help="score each image with its left-right mirror image too (test-time augmentation, as the "
        "planner does where its checkpoint's config.json says planner.mirror_tta)",
    )
    p.add_argument("--json", type=new_file, default=None, help="also write the full result as JSON here")
    return p


def main(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.through_stream and not args.with_detector:
        parser.error("--through-stream goes with --with-detector: it is what the detector and planner see")
    if args.latency < 0 or args.threads < 1:
        raise ValueError(f"--latency must be >= 0 and --threads >= 1, got {args.latency} and {args.threads}")
    from controller.evaluation.evaluate import evaluate_checkpoint_modes
    from controller.planning.latent.errors import LatentError
    from drone_inspect_core.dataset import DatasetError

    detector = None
    if args.with_detector:  # loaded first: a wrong checkpoint is said before the long scoring
        from perception.errors import DetectorCheckpointError
        from perception.image_detector import ImageDetector

        try:
            detector = ImageDetector.shipped() if args.detector is None else ImageDetector.load(args.detector)
        except DetectorCheckpointError as exc:
            say_error("dronectl evaluate", str(exc))
            return 1

    try:
        results = evaluate_checkpoint_modes(
            args.model, args.data, args.instructions, args.split, args.epsilon_px, args.seed,
            (args.mirror_tta,), flown=args.as_flown,
        )  # fmt: skip
    except (LatentError, DatasetError) as exc:  # a bad checkpoint, dataset or instruction file
        say_error("dronectl evaluate", str(exc))
        return 1
    for result in results:
        _print_result(result, detailed=result is results[0])
    with_detector = None
    if detector is not None:
        from controller.evaluation.with_detector import evaluate_with_detector

        try:
            with_detector = evaluate_with_detector(
                args.model, args.data, detector, args.split, args.epsilon_px, args.through_stream
            )
        except (LatentError, DatasetError, ValueError) as exc:
            say_error("dronectl evaluate", str(exc))
            return 1
        _print_with_detector(with_detector)
    if args.latency > 0:
        from controller.benchmarks.planner_latency import latency_on_dataset

        load_before = os.getloadavg()[0]
        lat = latency_on_dataset(args.model, args.data, args.split, args.latency, args.threads, args.backend)
        print(
            f"planner latency over {lat.decisions} decisions ({lat.backend}, {args.threads} threads): "
            f"mean {lat.mean_ms:.2f} ms, p50 {lat.p50_ms:.2f} ms, p99 {lat.p99_ms:.2f} ms, "
            f"max {lat.max_ms:.2f} ms; load average {load_before:.2f} before, "
            f"{os.getloadavg()[0]:.2f} after on {os.cpu_count()} CPUs"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        payload = results[0].__dict__ if len(results) == 1 else {r.instructions: r.__dict__ for r in results}
        if with_detector is not None:
            payload = {**payload, "with_detector": with_detector.as_dict()}
        write_json_atomic(args.json, payload, indent=1)
    return 0


def _print_with_detector(result: WithDetectorResult) -> None:
    twins = (
        f"; naming a colour (twins in the scene): {100 * result.twins_rank1:.2f}% of {result.twins}"
        if result.twins_rank1 is not None
        else ""
    )
    pictures = ", each image through the stream's JPEG" if result.through_stream else ""
    print(
        f"as the loop shows it (the detector taking the target, its twins painted over{pictures}): rank-1 "
        f"{100 * result.rank1:.2f}% of {result.n} images; no detection matched in {result.not_found}, "
        f"another target taken in {result.wrong_choice}{twins}"
    )
    if result.matched_rank1 is not None:
        print(f"  rank-1 where a detection matched: {100 * result.matched_rank1:.2f}%")
    if result.present_called_absent is not None and result.absent_called_present is not None:
        print(
            f"  not in view as the loop decides (a matching detection, the presence head by kind): present "
            f"called absent {100 * result.present_called_absent:.2f}% of {result.n}, absent called present "
            f"{100 * result.absent_called_present:.2f}% of {result.absent_pairs} pairs"
        )


def _print_result(result: EvalResult, detailed: bool) -> None:
    """One result: rank-1, axes, (first result only) the confusion matrix, groups and presence."""
    print(f"images: {result.n}   instructions: {result.instructions}")
    if result.parsed is not None:
        p = result.parsed
        print(f"the loop understood {p['understood']}, refused {p['refused']} and misread {p['misread']}")
    print(f"rank-1 accuracy: {100 * result.rank1:.2f}%")
    print(f"X accuracy: {100 * result.x_accuracy:.2f}%   Z accuracy: {100 * result.z_accuracy:.2f}%")
    if detailed:
        names = [a.name for a in ALL_ACTIONS]
        print("confusion (rows: true, columns: predicted)")
        print(" " * 12 + " ".join(f"{n:>11}" for n in names))
        for name, row in zip(names, result.confusion, strict=True):
            print(f"{name:>11} " + " ".join(f"{v:>11}" for v in row))
    if len(result.by_targets_in_view) > 1:
        parts = [
            f"{k} in view: {100 * g['rank1']:.2f}% of {g['n']}" for k, g in result.by_targets_in_view.items()
        ]
        print("rank-1 by targets in view: " + ", ".join(parts))
    for what, pr in (
        ("in these words", result.presence),
        ("by kind, the head alone: every pair as if the detector had matched it", result.presence_by_kind),
    ):  # as the loop decides, the detector included: --with-detector's last line
        if pr is None:
            continue
        print(
            f"not in view ({what}): AUROC {pr['auroc']:.4f}; at p < {pr['threshold']:.3f}: accuracy "
            f"{100 * pr['accuracy']:.2f}% ({pr['n_present']} present, {pr['n_absent']} absent pairs), "
            f"present called absent {100 * pr['false_absent_rate']:.2f}%, "
            f"absent called present {100 * pr['false_present_rate']:.2f}%, "
            f"mean absent confidence {pr['mean_absent_confidence']:.3f}"
        )
