"""Options that several commands share, declared once: the MAVLink signing key of a real vehicle.

`--signing-key FILE` flies a vehicle set up with a MAVLink 2 signing key: the file holds the 32 bytes
as 64 hex digits or base64, on one line (`drone_inspect_core.signing`). The link must be `udpin://`:
the relay in front of MAVSDK signs (MAVSDK cannot). A vehicle the command starts itself (sim-mavlink)
gets a key of its own per run; PX4 v1.15 SITL has no signing.
"""

from __future__ import annotations

import argparse

from drone_inspect_core.signing import SigningKey

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
