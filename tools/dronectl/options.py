"""What every command's options share, declared once: a parser that fails in one line, and the MAVLink
signing key of a real vehicle.

`CommandParser` is argparse's parser with one change: a bad option is one line on stderr,
`dronectl fly: argument --seed: invalid int value: 'x' (dronectl fly --help)`, exit 2, instead of
the usage block before it.

`--signing-key FILE` flies a vehicle set up with a MAVLink 2 signing key: the file holds the 32 bytes
as 64 hex digits or base64, on one line (`drone_inspect_core.signing`). The link must be `udpin://`:
the relay in front of MAVSDK signs (MAVSDK cannot). A vehicle the command starts itself (sim-mavlink)
gets a key of its own per run; PX4 v1.15 SITL has no signing.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from drone_inspect_core.files import write_json_atomic
from drone_inspect_core.signing import SigningKey

DEBUG = False
"""`dronectl --debug`: set by the command line before a command runs."""


def say_error(prog: str, text: str) -> None:
    """A command's one line for an error it caught itself; under --debug the traceback before it."""
    if DEBUG:
        traceback.print_exc()
    print(f"{prog}: {' '.join(text.split())}", file=sys.stderr)


class CommandParser(argparse.ArgumentParser):
    """An `argparse.ArgumentParser` whose errors are one line (see the module docstring)."""

    def error(self, message: str) -> NoReturn:
        text = " ".join(message.split("For further information visit")[0].split())  # pydantic's, in one line
        print(f"{self.prog}: {text} ({self.prog} --help)", file=sys.stderr)
        sys.exit(2)


MAX_SEED = 2**32 - 1


def seed_value(text: str) -> int:
    """An argparse type: a seed, 0..2^32-1 (numpy's and torch's range)."""
    return at_least(0, MAX_SEED)(text)


def at_least(minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse type: a whole number >= `minimum` (and <= `maximum`), said in one line otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            top = "" if maximum is None else f" and <= {maximum}"
            raise argparse.ArgumentTypeError(f"must be >= {minimum}{top}, got {value}")
        return value

    return parse


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def fraction_below_one(text: str) -> float:
    """An argparse type: a fraction in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and 0.0 <= value < 1.0):
        raise argparse.ArgumentTypeError(f"must be a fraction in [0, 1), got {text}")
    return value


def px4_instance_value(text: str) -> int | str:
    """An argparse type: a PX4 SITL instance, 0..9, or `auto`."""
    return text if text == "auto" else at_least(0, 9)(text)


def new_file(text: str) -> Path:
    """An argparse type: a file to write that does not exist yet (a result is never written over), in a
    folder that exists or can be made: checked before the work, not found out after it."""
    path = Path(text)
    if path.exists() or path.is_symlink():
        raise argparse.ArgumentTypeError(f"{path} exists: a result is never written over; give a new file")
    folder = next(parent for parent in path.absolute().parents if parent.exists())
    if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{path}: {folder} is not a folder this program can write in")
    return path


def write_result(path: Path | None, data: object) -> None:
    """A command's `--json FILE` (checked new by `new_file`), written whole, its folder made."""
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(path, data)


SIGNING_KEY_HELP = (
    "a real vehicle set up with MAVLink 2 signing: its 32-byte key, as 64 hex digits or base64 on one "
    "line (needs a udpin:// link; the relay signs for MAVSDK)"
)


def add_signing_key(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--signing-key", metavar="FILE", help=SIGNING_KEY_HELP)


def signing_key(args: argparse.Namespace) -> SigningKey | None:
    """The key named by `--signing-key`, loaded now (`SigningKeyError` names the file), or None."""
    path = getattr(args, "signing_key", None)
    return None if path is None else SigningKey.load(path)


def add_width_option(parser: argparse.ArgumentParser, scope: str = "") -> None:
    """`--width W`: the CNN's base width (`ModelConfig.base_width`) in place of the preset's."""
    parser.add_argument(
        "--width", type=at_least(1), default=None, help=f"{scope}override the preset's CNN base width"
    )


def add_distillation_options(parser: argparse.ArgumentParser, scope: str = "") -> None:
    """`--distill-from CHECKPOINT` and `--distill-weight W` (`TrainConfig.distill_from`, `distill_weight`);
    `scope` starts their help ("grounded: ")."""
    parser.add_argument(
        "--distill-from",
        type=Path,
        default=None,
        metavar="CHECKPOINT",
        help=f"{scope}also learn this planner checkpoint's scores of every training batch (distillation)",
    )
    parser.add_argument(
        "--distill-weight", type=float, default=None, help=f"{scope}weight of the distillation terms"
    )


def distillation_overrides(args: argparse.Namespace) -> dict[str, object]:
    """The `TrainConfig` fields the distillation options give; empty when neither was given."""
    given = {"distill_from": args.distill_from, "distill_weight": args.distill_weight}
    if args.distill_from is not None:
        given["distill_from"] = str(args.distill_from)
    return {key: value for key, value in given.items() if value is not None}
