"""The live video for the page: each camera frame as one binary WebSocket message.

A message is a 4-byte big-endian length, that many bytes of JSON (`views.frame_header`: the frame's
number, size and arrival time in Unix ms), then the JPEG. One message per frame keeps the header with
its picture, so the page draws the overlays of the frame it shows and measures the camera-to-page
latency of that very frame. Frames are encoded once, whatever the number of pages.
"""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Callable

import cv2

from controller.console.views import frame_header
from perception.types import Frame

HEADER_LENGTH = struct.Struct(">I")


def pack_frame(frame: Frame, jpeg_quality: int = 80) -> bytes:
    """The frame as one message: header length, JSON header, JPEG."""
    ok, jpeg = cv2.imencode(
        ".jpg", cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]
    )
    if not ok:
        raise ValueError(f"frame {frame.frame_number} could not be encoded as JPEG")
    header = json.dumps(frame_header(frame), separators=(",", ":")).encode()
    return HEADER_LENGTH.pack(len(header)) + header + jpeg.tobytes()


def unpack_frame(message: bytes) -> tuple[dict[str, object], bytes]:
    """(header, JPEG) of a message made by `pack_frame` (for the tests and the benchmark)."""
    (length,) = HEADER_LENGTH.unpack_from(message)
    return json.loads(message[4 : 4 + length]), message[4 + length :]


class FrameSender:
    """A camera-tap listener: encodes frames, about `max_fps` a second at most, and hands them to `send`."""

    def __init__(self, send: Callable[[bytes], None], max_fps: float = 30.0, jpeg_quality: int = 80) -> None:
        if not max_fps > 0:
            raise ValueError(f"max_fps must be > 0, got {max_fps!r}")
        self._send = send
        self._period_s = 1.0 / max_fps
        self._quality = jpeg_quality
        self._last_s = -1e9
        self._lock = threading.Lock()
        self.frames_sent = 0

    def __call__(self, frame: Frame) -> None:
        now = time.monotonic()
        with self._lock:
            if now - self._last_s < 0.8 * self._period_s:  # 0.8: a source at max_fps with jitter passes
                return
            self._last_s = now
            self.frames_sent += 1
        self._send(pack_frame(frame, self._quality))
