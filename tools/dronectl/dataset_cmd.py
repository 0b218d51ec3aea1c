"""`dronectl dataset check DIR [--json FILE]`: validate a dataset folder (rendered or flown) and count it.

    dronectl dataset check data/sim
    dronectl dataset check runs/flown --json runs/flown-check.json

Prints the counts per split, sector and kind; for a flown dataset how many captures were
flagged (their image-tracked and pose-derived offsets disagreed); for a collection flown in a
simulator, how many labels agree with the simulator's truth at the dataset's ε (the image-derived
label and the pose-derived one). Exit status 0 for a valid dataset, 1 when problems were found,
2 when it cannot be read at all.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from drone_inspect_core.dataset_check import Agreement, DatasetCheck, check_dataset
from drone_inspect_core.files import write_json_atomic
from drone_inspect_core.stats import Rate


def _counts(title: str, counts: dict[str, int], order: tuple[str, ...] = ()) -> str:
    names = [n for n in order if n in counts] + sorted(n for n in counts if n not in order)
    return f"{title}: " + ", ".join(f"{name} {counts[name]}" for name in names)


def _agreement(what: str, agreement: Agreement | None) -> str:
    if agreement is None or not agreement.n:
        return f"  {what}: no rows to compare"
    line = f"  {what}: {Rate(agreement.agree, agreement.n).describe()}"
    errors = agreement.error_quantiles()
    if errors is not None:
        line += (
            f"; offset from the truth's: median {errors['median_px']:.2f} px, p95 {errors['p95_px']:.2f} px, "
            f"max {errors['max_px']:.2f} px"
        )
    return line


def report_lines(check: DatasetCheck) -> list[str]:
    """What a person wants to read about a dataset."""
    from drone_inspect_core.dataset import SECTORS, SPLITS

    state = "complete" if check.complete else "INCOMPLETE (interrupted; `dronectl collect --resume` goes on)"
    lines = [
        f"{check.root}: {check.source} dataset, {check.rows} images, {state}, ε = {check.epsilon_px:g} px"
        + (f", {check.flights} flight(s)" if check.flights else ""),
        _counts("  splits", check.by_split, SPLITS),
        _counts("  sectors", check.by_sector, SECTORS),
        _counts("  kinds", check.by_kind),
    ]
    if check.source == "flown":
        share = 100.0 * check.flagged / check.rows if check.rows else 0.0
        reasons = ", ".join(f"{r}: {n}" for r, n in sorted(check.flagged_by_reason.items()))
        lines.append(
            f"  flagged (kept out of training): {check.flagged} ({share:.1f} %)"
            + (f" [{reasons}]" if reasons else "")
        )
    if check.truth_rows:
        lines.append(
            f"  labels against the simulator's truth at ε over the images kept for training "
            f"({check.truth_rows} rows carry truth):"
        )
        lines.append(_agreement("image-tracked (the label)", check.image_labels))
        lines.append(_agreement("pose-derived", check.pose_labels))
    lines += [f"  problem: {p}" for p in check.problems[:20]]
    if len(check.problems) > 20:
        lines.append(f"  ... and {len(check.problems) - 20} more problems")
    lines.append("  OK" if check.ok else f"  {len(check.problems)} problem(s)")
    return lines


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="dronectl dataset", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    check = sub.add_parser("check", help="validate a dataset folder and print its counts")
    check.add_argument("dir", type=Path, help="the dataset folder (dataset.json, manifest.jsonl, images/)")
    check.add_argument("--json", type=Path, default=None, help="also write the figures to this JSON file")
    check.add_argument("--no-images", action="store_true", help="do not decode every image (faster)")
    args = parser.parse_args(argv)
    from drone_inspect_core.dataset import DatasetError

    try:
        result = check_dataset(args.dir, decode_images=not args.no_images)
    except DatasetError as exc:
        print(f"dronectl dataset check: {exc}", file=sys.stderr)
        return 2
    print("\n".join(report_lines(result)))
    if args.json is not None:
        try:
            write_json_atomic(args.json, result.as_dict())
        except OSError as exc:
            print(f"dronectl dataset check: --json {args.json}: {exc.strerror or exc}", file=sys.stderr)
            return 2
    return 0 if result.ok else 1
