"""MAVLink 2 message signing: the key, signing what we send, and checking what we receive.

A signed MAVLink 2 frame carries 13 more bytes: a link id, a 48-bit timestamp (units of 10 µs since
2015-01-01 UTC) and the first 6 bytes of SHA-256(key + frame up to the timestamp). Whoever holds the
32-byte key can command the vehicle; nobody else can, nor replay an old frame (each stream's
timestamps must grow). The project signs every link it starts with a key made for that run
(`SigningKey.generate()`), and a real vehicle set up with a key is flown with `--signing-key FILE`.

A key file holds the 32 bytes as 64 hex digits or as base64 (44 characters), on one line; blank
lines and `#` comments are ignored. `SigningKey.load` names the file and what is wrong with it.

`FrameSigner` signs with pymavlink's own packing. `FrameVerifier` checks signatures itself:
pymavlink records a new stream's timestamp before it checks the signature, so one forged frame
with a far-future timestamp would make every genuine frame of that stream "old". Here nothing
is remembered of a frame whose signature is wrong.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import logging
import secrets
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

KEY_BYTES = 32
SIGNATURE_BYTES = 13  # link id (1) + timestamp (6) + signature (6)
SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z
NEW_STREAM_WINDOW = 60 * 100_000
"""A stream first heard may be at most a minute behind the newest timestamp seen (the MAVLink rule)."""
_HEADER_V2 = 10
_STX_V2 = 0xFD


class SigningKeyError(ValueError):
    """A key file or key text that is not a MAVLink signing key; the message says why."""


def signing_timestamp_now() -> int:
    """Now, in MAVLink signing units: 10 µs since 2015-01-01 UTC."""
    return int((time.time() - SIGNING_EPOCH_S) * 100_000)


@dataclass(frozen=True)
class SigningKey:
    """A 32-byte MAVLink 2 signing secret (its `repr` never shows it)."""

    secret: bytes = field(repr=False)

    def __post_init__(self) -> None:
        if len(self.secret) != KEY_BYTES:
            raise SigningKeyError(f"a MAVLink signing key is {KEY_BYTES} bytes, got {len(self.secret)}")
        if not any(self.secret):
            raise SigningKeyError("an all-zero key means 'signing off' in MAVLink: use a real secret")

    @classmethod
    def generate(cls) -> SigningKey:
        """A fresh random key (one per run)."""
        return cls(secrets.token_bytes(KEY_BYTES))

    @classmethod
    def from_text(cls, text: str) -> SigningKey:
        """From 64 hex digits or base64 of 32 bytes (surrounding space, blank and `#` lines ignored)."""
        lines = [line.strip() for line in text.splitlines()]
        lines = [line for line in lines if line and not line.startswith("#")]
        if len(lines) != 1:
            raise SigningKeyError(
                f"expected the key on one line (64 hex digits or base64 of {KEY_BYTES} bytes), "
                f"found {len(lines)} lines"
            )
        word = lines[0]
        if len(word) == 2 * KEY_BYTES and all(c in "0123456789abcdefABCDEF" for c in word):
            return cls(bytes.fromhex(word))
        try:
            secret = base64.b64decode(word, validate=True)
        except (binascii.Error, ValueError):
            raise SigningKeyError(
                f"not 64 hex digits and not base64 (a line of {len(word)} characters)"
            ) from None
        return cls(secret)

    @classmethod
    def load(cls, path: str | Path) -> SigningKey:
        """The key in `path`; `SigningKeyError` naming the file on any problem."""
        path = Path(path)
        try:
            text = path.read_text(encoding="ascii")
        except FileNotFoundError:
            raise SigningKeyError(f"signing key file {path} does not exist") from None
        except IsADirectoryError:
            raise SigningKeyError(f"signing key file {path} is a folder") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SigningKeyError(f"signing key file {path} cannot be read: {exc}") from None
        try:
            return cls.from_text(text)
        except SigningKeyError as exc:
            raise SigningKeyError(f"signing key file {path}: {exc}") from None

    def hex(self) -> str:
        """The key as 64 hex digits (how it travels to a child process, through a pipe)."""
        return self.secret.hex()


def is_signed(frame: bytes) -> bool:
    """Whether `frame` (one whole MAVLink frame) is a MAVLink 2 frame with the signed flag."""
    return len(frame) > _HEADER_V2 and frame[0] == _STX_V2 and bool(frame[2] & mavlink.MAVLINK_IFLAG_SIGNED)


class FrameVerifier:
    """Checks signed frames against one key, with per-stream replay protection (see the module doc)."""

    def __init__(self, key: SigningKey) -> None:
        self._secret = key.secret
        self._streams: dict[tuple[int, int, int], int] = {}
        self._newest = signing_timestamp_now()
        self.accepted = 0
        self.rejected = 0

    def verify(self, frame: bytes) -> bool:
        """True for a correctly signed, fresh MAVLink 2 frame (one whole frame, as parsed)."""
        ok = self._check(bytes(frame))
        if ok:
            self.accepted += 1
        else:
            self.rejected += 1
        return ok

    def _check(self, frame: bytes) -> bool:
        if not is_signed(frame) or len(frame) != _HEADER_V2 + frame[1] + 2 + SIGNATURE_BYTES:
            return False
        digest = hashlib.sha256(self._secret + frame[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, frame[-6:]):
            return False
        link_id = frame[-13]
        low, high = struct.unpack("<IH", frame[-12:-6])
        timestamp = low | high << 32
        stream = (link_id, frame[5], frame[6])  # link, system, component
        last = self._streams.get(stream)
        if last is None and timestamp + NEW_STREAM_WINDOW < self._newest:
            return False  # a stream first heard with an old timestamp: a replay
        if last is not None and timestamp <= last:
            return False  # not newer than what this stream already sent: a replay
        self._streams[stream] = timestamp
        self._newest = max(self._newest, timestamp)
        return True


class FrameSigner:
    """Packs messages as signed MAVLink 2 frames with one key, keeping each message's sender and sequence."""

    def __init__(self, key: SigningKey, link_id: int = 0) -> None:
        self._mav = mavlink.MAVLink(None)
        self._mav.signing.secret_key = key.secret
        self._mav.signing.sign_outgoing = True
        self._mav.signing.link_id = link_id
        self._mav.signing.timestamp = signing_timestamp_now()

    def sign(self, message: mavlink.MAVLink_message) -> bytes:
        """`message` (as parsed from the wire: MAVLink 1 or 2) re-packed signed, same sender and sequence.

        Raises what pymavlink raises for a message that cannot be packed."""
        mav = self._mav
        mav.srcSystem, mav.srcComponent, mav.seq = (
            message.get_srcSystem(),
            message.get_srcComponent(),
            message.get_seq(),
        )
        mav.signing.timestamp = max(mav.signing.timestamp, signing_timestamp_now())
        return bytes(message.pack(mav))


def enable_signing(mav: mavlink.MAVLink, key: SigningKey, link_id: int = 0) -> None:
    """Make everything `mav` packs from now on a signed MAVLink 2 frame (a vehicle's own sender)."""
    mav.signing.secret_key = key.secret
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = max(mav.signing.timestamp, signing_timestamp_now())
