"""`dronectl calibrate-presence`: choose the planner's "not in view" threshold on validation scenes.

    dronectl calibrate-presence --model controller/planning/assets/latent_cpu --data data/pval data/pval_twins

Asks the checkpoint's presence head, as the centring loop asks before it takes a detection for the
target (by the kind alone, with the mirror image where the planner mirrors), about every test and
empty image of the validation folders; chooses the highest threshold that calls at most
--max-false-absent of the present pairs absent; prints the rates at it on those folders and writes
it to the checkpoint's config.json (`planner.presence_threshold`, with how it was chosen) unless
--dry-run. Validation folders must be scenes the checkpoint never trained on and that no test uses:
held-out figures come from `dronectl evaluate` on other folders.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dronectl.options import CommandParser, fraction_below_one, new_file, say_error, write_result

PROG = "dronectl calibrate-presence"


def build_parser() -> argparse.ArgumentParser:
    from controller.evaluation.presence_calibration import DEFAULT_MAX_FALSE_ABSENT

    p = CommandParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--model", type=Path, required=True, help="checkpoint folder (its config.json is updated)")
    p.add_argument(
        "--data",
        type=Path,
        nargs="+",
        required=True,
        help="validation dataset folder(s): scenes neither training nor any test set drew",
    )
    p.add_argument(
        "--max-false-absent",
        type=fraction_below_one,
        default=DEFAULT_MAX_FALSE_ABSENT,
        help="share of the validation present pairs the threshold may call absent (default %(default)s)",
    )
    p.add_argument("--dry-run", action="store_true", help="print the threshold, write nothing")
    p.add_argument("--json", type=new_file, default=None, help="also write the calibration as JSON here")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    from controller.evaluation.presence_calibration import calibrate_presence, write_presence_threshold
    from controller.planning.latent.errors import LatentError

    try:
        calibration = calibrate_presence(args.model, args.data, args.max_false_absent)
        if not args.dry_run:
            write_presence_threshold(args.model, calibration)
    except (LatentError, OSError) as exc:  # a bad checkpoint or folder: one line
        say_error(PROG, str(exc))
        return 1
    r = calibration.result
    print(
        f"presence threshold {calibration.threshold:.4f} (asked by kind, "
        f"{'with' if calibration.mirror else 'without'} the mirror image) on {r.n_present} present and "
        f"{r.n_absent} absent validation pairs from {', '.join(calibration.validation)}"
    )
    print(
        f"on these validation pairs: AUROC {r.auroc:.4f}, present called absent "
        f"{100 * r.false_absent_rate:.2f}% (budget {100 * calibration.max_false_absent:.2f}%), "
        f"absent called present {100 * r.false_present_rate:.2f}%"
    )
    print(
        "not written (--dry-run)"
        if args.dry_run
        else f"written to {args.model / 'config.json'} (planner.presence_threshold)"
    )
    write_result(args.json, {"threshold": calibration.threshold, **calibration.record()})
    return 0
