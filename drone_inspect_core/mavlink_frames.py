"""Whole MAVLink frames in a byte stream or a datagram, found by their headers and checked by their CRC,
without decoding their payloads.

For the links where every frame is counted, forwarded or recorded and few are read: a bridge's simulator
link (PX4 answers every 4 ms tick), the relay's .tlog (every message of a flight). A frame counts when its
start marker (MAVLink 2 or 1), its length and its CRC (X.25 with the message's CRC extra) agree and its id
is a message we know (ArduPilot's dialect, which holds every common message): an unknown id cannot be
checked, and random bytes pass as one. A candidate that fails costs one byte, not the length its header
claims, and bytes before a start marker are skipped, so a bad header never swallows the good frames after
it. The signature of a signed frame is part of the frame; it is not checked here
(`drone_inspect_core.signing` does that).
"""

from __future__ import annotations

from typing import NamedTuple

from pymavlink.dialects.v20 import ardupilotmega as mavlink

_MARKERS = (mavlink.PROTOCOL_MARKER_V2, mavlink.PROTOCOL_MARKER_V1)
_V2_HEADER_BYTES, _V1_HEADER_BYTES = 10, 6
_CRC_EXTRA = {msg_id: message.crc_extra for msg_id, message in mavlink.mavlink_map.items()}


class MavlinkFrame(NamedTuple):
    """Where one whole frame lies in the scanned bytes: `data[start:end]` is the frame,
    `data[payload_start:payload_end]` its payload as sent (MAVLink 2 cuts trailing zeros)."""

    msg_id: int
    start: int
    payload_start: int
    payload_end: int
    end: int

    @property
    def name(self) -> str:
        return name_of(self.msg_id)


def name_of(msg_id: int) -> str:
    """The message name of a frame `scan` found."""
    return mavlink.mavlink_map[msg_id].msgname


def crc(checked: bytes, crc_extra: int) -> int:
    """MAVLink's CRC: X.25 over the frame after its start marker, then the message's CRC extra."""
    return mavlink.x25crc(checked + bytes((crc_extra,))).crc


def scan(data: bytes, more_to_come: bool = True) -> tuple[list[MavlinkFrame], int, int]:
    """The whole frames of known messages in `data`, how many bytes of it were used up, and how many bad
    candidates and runs of stray bytes were skipped. `more_to_come` (a stream): a frame not yet whole at
    the end is left for the rest to come; otherwise (a datagram) it is a bad candidate like any other."""
    frames: list[MavlinkFrame] = []
    at, bad, size = 0, 0, len(data)
    while at < size:
        marker = data[at]
        if marker not in _MARKERS:
            following = [i for i in (data.find(m, at + 1) for m in _MARKERS) if i >= 0]
            at = min(following, default=size)
            bad += 1
            continue
        found = _frame_at(data, at)
        if found is None and more_to_come:
            break  # not yet whole: the rest comes later
        if found is None or not _checks(data, found):
            bad += 1
            at += 1
            continue
        frames.append(found)
        at = found.end
    return frames, at, bad


def _frame_at(data: bytes, at: int) -> MavlinkFrame | None:
    """The frame whose start marker is at `at`, as its header describes it; None if `data` ends first."""
    header = _V2_HEADER_BYTES if data[at] == mavlink.PROTOCOL_MARKER_V2 else _V1_HEADER_BYTES
    if len(data) - at < header:
        return None
    if header == _V2_HEADER_BYTES:
        msg_id = data[at + 7] | data[at + 8] << 8 | data[at + 9] << 16
        signed = data[at + 2] & mavlink.MAVLINK_IFLAG_SIGNED
        signature = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if signed else 0
    else:
        msg_id, signature = data[at + 5], 0
    crc_at = at + header + data[at + 1]
    end = crc_at + 2 + signature
    return None if end > len(data) else MavlinkFrame(msg_id, at, at + header, crc_at, end)


def _checks(data: bytes, frame: MavlinkFrame) -> bool:
    """Whether `frame` is of a message we know and its CRC matches."""
    extra = _CRC_EXTRA.get(frame.msg_id)
    at, crc_at = frame.start, frame.payload_end
    return extra is not None and crc(data[at + 1 : crc_at], extra) == data[crc_at] | data[crc_at + 1] << 8
