"""`dronectl calibrate-presence`: choose the planner's "not in view" threshold on validation scenes.

    dronectl calibrate-presence --model controller/planning/assets/latent_cpu --data data/pval data/pval_twins

Reads every test image of the validation folders as the centring loop reads a frame before it takes a
detection for the target: the detector (--detector, default the shipped one) finds the named target
(its kind; among twins, its colour), and where it does the checkpoint's presence head is asked by kind
on the picture the planner would see; the same for every kind none of the image's targets has. Chooses
the threshold at which the loop makes the fewest wrong calls there (present targets called absent plus
absent ones called present, as shares); prints the rates at it on those folders and writes it to the
checkpoint's config.json (`planner.presence_threshold`, with how it was chosen) unless --dry-run.
Validation folders must be scenes the checkpoint never trained on and that no test uses: held-out
figures come from `dronectl evaluate --with-detector` on other folders.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dronectl.options import CommandParser, new_file, say_error, write_result

PROG = "dronectl calibrate-presence"


def build_parser() -> argparse.ArgumentParser:
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
        "--detector",
        type=Path,
        default=None,
        help="the image detector's checkpoint the loop flies with (default: the shipped one)",
    )
    p.add_argument("--dry-run", action="store_true", help="print the threshold, write nothing")
    p.add_argument("--json", type=new_file, default=None, help="also write the calibration as JSON here")
    return p


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    from controller.evaluation.presence_calibration import calibrate_presence, write_presence_threshold
    from controller.planning.latent.errors import LatentError
    from drone_inspect_core.dataset import DatasetError
    from perception.errors import DetectorCheckpointError
    from perception.image_detector import SHIPPED_DIR, ImageDetector

    try:
        detector = ImageDetector.shipped() if args.detector is None else ImageDetector.load(args.detector)
        shipped = "/".join(SHIPPED_DIR.parts[-3:])  # perception/assets/detector, wherever the checkout is
        name = f"shipped ({shipped})" if args.detector is None else str(args.detector)
        calibration = calibrate_presence(args.model, args.data, detector, name)
        if not args.dry_run:
            write_presence_threshold(args.model, calibration)
    except (LatentError, DetectorCheckpointError, DatasetError, OSError) as exc:  # bad input: one line
        say_error(PROG, str(exc))
        return 1
    r = calibration.result
    print(
        f"presence threshold {calibration.threshold:.4f} (asked by kind where the detector matched, "
        f"{'with' if calibration.mirror else 'without'} the mirror image; detector: "
        f"{calibration.detector}) on "
        f"{r.n_present} present and {r.n_absent} absent validation pairs from "
        f"{', '.join(calibration.validation)}"
    )
    print(
        f"as the loop decides on these pairs: present called absent {100 * r.false_absent_rate:.2f}% "
        f"({r.present_unmatched} the detector matched nothing for), absent called present "
        f"{100 * r.false_present_rate:.2f}% (the detector matched {r.absent_matched} absent pairs)"
    )
    print(
        "not written (--dry-run)"
        if args.dry_run
        else f"written to {args.model / 'config.json'} (planner.presence_threshold)"
    )
    write_result(args.json, {"threshold": calibration.threshold, **calibration.record()})
    return 0
