"""An MJPEG-over-HTTP stream read part by part, each JPEG decoded by OpenCV, its headers kept.

OpenCV's FFmpeg reader decodes `multipart/x-mixed-replace` streams but drops each part's headers, and
with them the scene stamp a simulator's render process sends (`drone_inspect_core.video_stamps`). This
reader speaks the same stream itself: HTTP GET, the multipart boundary from the Content-Type, then for
each part its headers and its `Content-Length` bytes (or, where a camera sends no length, the bytes up
to the next boundary), decoded with `cv2.imdecode`. It has the subset of `cv2.VideoCapture`'s
interface `StreamCamera` uses (`isOpened`, `read`, `get`, `release`), plus `scene_s`, the last part's
stamp. As FFmpeg does, it is open only once the stream has given a frame that decodes.

Hostile or broken input is bounded: a part over `MAX_PART_BYTES`, a header line over
`MAX_LINE_BYTES`, more than `MAX_HEADERS` headers or `MAX_SKIP_BYTES` of bytes that are no part end
the stream (the camera's reconnect takes over); a part that does not decode is skipped, and
`MAX_BAD_PARTS` of them in a row end the stream too. A JPEG whose header says it is larger than
`MAX_PIXELS` is not decoded (a few bytes can announce gigabytes of pixels), and opening must get its
first frame within the open timeout in all, however slowly the bytes come. Every socket
read is bounded by the read timeout; `release()` from another thread ends a blocked read.
"""

from __future__ import annotations

import contextlib
import http.client
import io
import logging
import socket
import threading
import time
from urllib.parse import urlsplit

import cv2
import numpy as np

from drone_inspect_core.video_stamps import SCENE_STAMP_HEADER, parse_scene_stamp

log = logging.getLogger(__name__)

MAX_PART_BYTES = 16 * 1024 * 1024
MAX_LINE_BYTES = 4096
MAX_HEADERS = 32
MAX_SKIP_BYTES = 1024 * 1024
MAX_BAD_PARTS = 30  # parts in a row that do not decode before the stream counts as broken
MAX_PIXELS = 4096 * 4096  # a part showing a larger picture is not decoded (memory)


class MjpegStreamError(Exception):
    """The stream is not (or no longer) a readable MJPEG stream; the message says why."""


def boundary_of(content_type: str) -> bytes:
    """The multipart boundary of a `multipart/x-mixed-replace` Content-Type (MjpegStreamError if none)."""
    kind, _, params = content_type.partition(";")
    if kind.strip().lower() != "multipart/x-mixed-replace":
        raise MjpegStreamError(f"not an MJPEG stream (Content-Type {content_type!r})")
    for param in params.split(";"):
        key, _, value = param.strip().partition("=")
        if key.strip().lower() == "boundary" and value.strip().strip('"'):
            boundary = value.strip().strip('"')
            return (boundary if boundary.startswith("--") else "--" + boundary).encode("latin-1")
    raise MjpegStreamError(f"no boundary in Content-Type {content_type!r}")


class MjpegParts:
    """The parts of a multipart body read from a binary file object: `next_part()` → (headers, body)."""

    def __init__(self, stream: io.BufferedIOBase, boundary: bytes) -> None:
        self._stream = stream
        self._boundary = boundary
        self._at_part = False  # the boundary before the next part was read already
        self.deadline: float | None = None  # time.monotonic() past which reading fails (opening)

    def _line(self) -> bytes:
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise MjpegStreamError("no frame within the open timeout")
        line = self._stream.readline(MAX_LINE_BYTES + 1)
        if not line:
            raise MjpegStreamError("the stream ended")
        if len(line) > MAX_LINE_BYTES:
            raise MjpegStreamError(
                f"a line of over {MAX_LINE_BYTES} bytes where a part's header was expected"
            )
        return line

    def next_part(self) -> tuple[dict[str, str], bytes]:
        """The next part's headers (names lower-case) and body."""
        skipped = 0
        while not self._at_part:  # up to the boundary: a preamble, the CRLF that ends the previous body
            line = self._line()
            if line.rstrip(b"\r\n") == self._boundary:
                break
            if line.rstrip(b"\r\n") == self._boundary + b"--":
                raise MjpegStreamError("the stream ended (closing boundary)")
            skipped += len(line)
            if skipped > MAX_SKIP_BYTES:
                raise MjpegStreamError(f"no part boundary in {MAX_SKIP_BYTES} bytes")
        self._at_part = False
        headers: dict[str, str] = {}
        for count in range(MAX_HEADERS + 1):
            if (line := self._line().rstrip(b"\r\n")) == b"":
                break
            if count == MAX_HEADERS:
                raise MjpegStreamError(f"a part with more than {MAX_HEADERS} headers")
            name, sep, value = line.decode("latin-1").partition(":")
            if sep:
                headers[name.strip().lower()] = value.strip()
        length = headers.get("content-length")
        if length is None:
            return headers, self._body_to_boundary()
        try:
            size = int(length)
        except ValueError:
            raise MjpegStreamError(f"a part's Content-Length is not a number: {length!r}") from None
        if not 0 < size <= MAX_PART_BYTES:
            raise MjpegStreamError(f"a part of {size} bytes (at most {MAX_PART_BYTES})")
        body = self._stream.read(size)
        if len(body) < size:
            raise MjpegStreamError("the stream ended inside a part")
        return headers, body

    def _body_to_boundary(self) -> bytes:
        """A part without Content-Length: its lines up to the next boundary, which is consumed here."""
        chunks: list[bytes] = []
        size = 0
        while (line := self._line()).rstrip(b"\r\n") != self._boundary:
            chunks.append(line)
            size += len(line)
            if size > MAX_PART_BYTES:
                raise MjpegStreamError(f"a part of over {MAX_PART_BYTES} bytes without a Content-Length")
        self._at_part = True
        body = b"".join(chunks)
        return body[:-2] if body.endswith(b"\r\n") else body


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's frame header (SOF0-SOF15 but DHT, JPG, DAC), None if none is found."""
    if not data.startswith(b"\xff\xd8"):
        return None
    i = 2
    while i + 9 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length
            i += 2
            continue
        length = int.from_bytes(data[i + 2 : i + 4], "big")
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            height = int.from_bytes(data[i + 5 : i + 7], "big")
            width = int.from_bytes(data[i + 7 : i + 9], "big")
            return width, height
        if length < 2:
            return None
        i += 2 + length
    return None


TOO_LARGE = np.empty(0, np.uint8)
"""`decode_jpeg`'s answer for a JPEG whose header announces more than `MAX_PIXELS` (not decoded)."""


def decode_jpeg(data: bytes) -> np.ndarray | None:
    """A JPEG as BGR through OpenCV; None where it is none, `TOO_LARGE` (undecoded) where its header
    announces more than `MAX_PIXELS` (a few bytes can announce gigabytes of pixels)."""
    size = jpeg_size(data)
    if size is None:
        return None
    if not 0 < size[0] * size[1] <= MAX_PIXELS:
        return TOO_LARGE
    try:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:  # OpenCV refuses some broken pictures by raising
        return None


class _JpegCounts:
    """What both captures count of the pictures they could not use."""

    skipped: int
    oversized: int

    def _decode(self, body: bytes) -> np.ndarray | None:
        """A JPEG as BGR, or None (counted in `skipped`) where it is no picture or announces too many
        pixels (counted in `oversized` too)."""
        bgr = decode_jpeg(body)
        self.oversized += bgr is TOO_LARGE
        if bgr is None or bgr is TOO_LARGE:
            self.skipped += 1
            return None
        return bgr


class MjpegHttpCapture(_JpegCounts):
    """`cv2.VideoCapture`'s reading interface on an `http://` MJPEG URL, keeping each part's scene stamp."""

    def __init__(self, url: str, open_timeout_s: float, read_timeout_s: float) -> None:
        self.url = url
        self.scene_s: float | None = None
        self.skipped = 0  # parts that did not decode
        self.oversized = 0  # of them, parts whose header announced more than MAX_PIXELS
        self._conn: http.client.HTTPConnection | None = None
        self._parts: MjpegParts | None = None
        self._first: tuple[np.ndarray, float | None] | None = None  # the frame that opened the stream
        self.error: str | None = None
        parts = urlsplit(url)
        if parts.scheme != "http" or not parts.hostname:
            self.error = f"not an http:// URL: {url!r}"
            return
        path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        try:
            conn = http.client.HTTPConnection(parts.hostname, parts.port or 80, timeout=open_timeout_s)
            self._conn = conn
            conn.request("GET", path, headers={"Accept": "multipart/x-mixed-replace"})
            response = conn.getresponse()
            if response.status != 200:
                raise MjpegStreamError(f"HTTP {response.status} {response.reason}")
            boundary = boundary_of(response.getheader("Content-Type", ""))
            self._parts = MjpegParts(response, boundary)
            self._parts.deadline = time.monotonic() + open_timeout_s
            ok, bgr = self.read()
            if not ok or bgr is None:
                raise MjpegStreamError(f"no frame: {self.error}")
            self._parts.deadline = None
            self._first = (bgr, self.scene_s)
            if conn.sock is not None:
                conn.sock.settimeout(read_timeout_s)
        except (OSError, http.client.HTTPException, MjpegStreamError) as exc:
            self.error = str(exc) or type(exc).__name__
            self.release()

    def isOpened(self) -> bool:  # cv2.VideoCapture's name
        return self._parts is not None

    def get(self, prop: int) -> float:
        """No property is known of a stream read this way (0.0, as OpenCV answers for an unknown one)."""
        return 0.0

    def read(self) -> tuple[bool, np.ndarray | None]:
        """The next part that decodes, as BGR (`scene_s` set from its stamp); (False, None) once the
        stream fails, stalls past the read timeout or is released."""
        if self._first is not None and self._parts is not None:
            (bgr, self.scene_s), self._first = self._first, None
            return True, bgr
        bad = 0
        while self._parts is not None:
            try:
                headers, body = self._parts.next_part()
            except (OSError, ValueError, http.client.HTTPException, MjpegStreamError) as exc:
                self.error = str(exc) or type(exc).__name__
                log.debug("MJPEG %s: %s", self.url, self.error)
                return False, None
            bgr = self._decode(body)
            if bgr is None:
                bad += 1
                if bad >= MAX_BAD_PARTS:
                    self.error = f"{bad} parts in a row are no picture OpenCV can decode"
                    return False, None
                continue
            self.scene_s = parse_scene_stamp(headers.get(SCENE_STAMP_HEADER.lower()))
            return True, bgr
        return False, None

    def release(self) -> None:
        """Close the connection (a read blocked in another thread returns False)."""
        self._parts = None
        conn, self._conn = self._conn, None
        if conn is not None:
            _shut_down(conn)
            conn.close()


class MjpegPullCapture(_JpegCounts):
    """The same interface on a simulator's MJPEG server read picture by picture: each `read()` asks
    `/frame.jpg?fresh=1` for a frame published after the request came (the render process then draws it:
    it draws nothing nobody asked for) and keeps its scene stamp. `url` names the server (its stream URL
    does). A response that is not one bounded JPEG (`MAX_PART_BYTES`, `MAX_PIXELS`) is no frame;
    `MAX_BAD_PARTS` of them in a row end the reading (the camera's reconnect takes over)."""

    def __init__(self, url: str, open_timeout_s: float, read_timeout_s: float) -> None:
        self.url = url
        self.scene_s: float | None = None
        self.skipped = 0
        self.oversized = 0
        self.error: str | None = None
        self._read_timeout_s = read_timeout_s
        self._conn: http.client.HTTPConnection | None = None
        self._open = False
        parts = urlsplit(url)
        if parts.scheme != "http" or not parts.hostname:
            self.error = f"not an http:// URL: {url!r}"
            return
        self._server = (parts.hostname, parts.port or 80)
        self._open = True  # `_pull` reads it: a `release()` from another thread ends the pulling
        self._open = self._pull(open_timeout_s)[0]  # a picture proves it open; the reads ask for their own

    def isOpened(self) -> bool:  # cv2.VideoCapture's name
        return self._open

    def get(self, prop: int) -> float:
        return 0.0

    def read(self) -> tuple[bool, np.ndarray | None]:
        """A picture drawn after this call (`scene_s` its stamp); (False, None) once the server fails,
        answers nothing within the read timeout or the capture is released."""
        return self._pull(self._read_timeout_s)

    def _pull(self, timeout_s: float) -> tuple[bool, np.ndarray | None]:
        for _ in range(MAX_BAD_PARTS):
            if not self._open:
                return False, None
            try:
                headers, body = self._get(timeout_s)
            except (OSError, ValueError, http.client.HTTPException, MjpegStreamError) as exc:
                self.error = str(exc) or type(exc).__name__
                log.debug("MJPEG %s: %s", self.url, self.error)
                return False, None
            bgr = self._decode(body)
            if bgr is not None:
                self.scene_s = parse_scene_stamp(headers.get(SCENE_STAMP_HEADER.lower()))
                return True, bgr
        self.error = f"{MAX_BAD_PARTS} answers in a row are no picture OpenCV can decode"
        return False, None

    def _get(self, timeout_s: float) -> tuple[dict[str, str], bytes]:
        """One picture's headers and bytes, all within `timeout_s` (a trickle is cut off at its end)."""
        conn = http.client.HTTPConnection(*self._server, timeout=timeout_s)
        self._conn = conn
        cut_off = threading.Timer(timeout_s, _shut_down, args=(conn,))
        cut_off.daemon = True
        try:
            conn.connect()
            cut_off.start()
            conn.request("GET", "/frame.jpg?fresh=1", headers={"Accept": "image/jpeg"})
            response = conn.getresponse()
            if response.status != 200:
                raise MjpegStreamError(f"HTTP {response.status} {response.reason}")
            length = response.getheader("Content-Length")
            if length is not None and not (length.isdigit() and 0 < int(length) <= MAX_PART_BYTES):
                raise MjpegStreamError(f"a picture of {length!r} bytes (at most {MAX_PART_BYTES})")
            body = response.read(MAX_PART_BYTES + 1)
            if len(body) > MAX_PART_BYTES:
                raise MjpegStreamError(f"a picture of over {MAX_PART_BYTES} bytes")
            return {k.lower(): v for k, v in response.getheaders()}, body
        finally:
            cut_off.cancel()
            conn.close()

    def release(self) -> None:
        """No more reads (one blocked in another thread returns False)."""
        self._open = False
        if self._conn is not None:
            _shut_down(self._conn)


def _shut_down(conn: http.client.HTTPConnection) -> None:
    """End a connection's socket both ways: a read blocked on it in another thread returns."""
    sock = conn.sock
    if sock is not None:
        with contextlib.suppress(OSError):  # not connected any more
            sock.shutdown(socket.SHUT_RDWR)
