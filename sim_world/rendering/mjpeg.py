"""The simulated drone's video: an HTTP MJPEG server, as IP cameras and drone video bridges serve.

Push design: whoever renders calls `publish(image, truth)`; the frame is JPEG-encoded
once, in the caller's thread, and every connected client is woken to send it. A slow
client skips frames and always gets the newest one; nothing is queued, so the
server adds no latency of its own and never grows a backlog.

Pictures on demand (`on_demand=True`, the simulators' render processes): a reader that wants one
picture now asks `/frame.jpg`, and a `/truth.json` of the latest frame asks for the truth of
now; each is a demand the publisher answers (`asked()`, then `publish(..., answers=N)` or
`answer(N)`) with a scene read after the demand came, so a publisher with no stream client
connected renders nothing nobody asked for (`wait_asked()`).

Endpoints:
- `/stream.mjpg`: `multipart/x-mixed-replace` JPEG parts with `Content-Length`
  (what OpenCV/FFmpeg, browsers and VLC read); starts with the latest frame. A part of a
  frame published with a scene stamp carries it (`drone_inspect_core.video_stamps`).
- `/frame.jpg`: the latest frame (on demand: a picture drawn for the request), header
  `X-Frame-Number` (and the scene stamp, if it has one); `/frame.jpg?fresh=1`: a frame published
  after the request came (504 if none within the client timeout).
- `/truth.json`: the truth published with the latest frame (on demand: of a scene read after the
  request came, waiting up to `TRUTH_WAIT_S`), or with frame N via
  `/truth.json?frame=N` (the last `truth_history` frames). For the test harness
  only: the controller must never read it.

Binds loopback by default. Imports nothing of ours but the ground floor (it belongs to the simulated vehicle).
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from types import TracebackType
from typing import Any
from urllib.parse import parse_qs, urlsplit

import cv2
import numpy as np

from drone_inspect_core.video_stamps import SCENE_STAMP_HEADER, format_scene_stamp

log = logging.getLogger(__name__)

BOUNDARY = "mjpegframe"
_WAKE_INTERVAL_S = 0.2  # how often idle stream handlers look at the closing flag
TRUTH_WAIT_S = 0.5
"""On demand: how long a `/truth.json` of the latest frame waits for the publisher's answer (then the
latest truth there is, as without demands): well inside the 1 s its readers wait for an answer."""


def encode_jpeg(image_rgb: np.ndarray, quality: int) -> bytes:
    """An RGB uint8 (H, W, 3) image as the stream sends it: OpenCV's JPEG at `quality`, its default
    4:2:0 chroma (one colour for each 2×2 pixels, as most cameras' streams)."""
    image = np.asarray(image_rgb)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"a JPEG frame needs an RGB uint8 (H, W, 3) image, got {image.dtype} {image.shape}")
    ok, buf = cv2.imencode(
        ".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [int(cv2.IMWRITE_JPEG_QUALITY), quality]
    )
    if not ok:
        raise RuntimeError(f"JPEG encoding failed for an image of shape {image.shape}")
    return buf.tobytes()


@dataclass(frozen=True)
class PublishedFrame:
    """One encoded frame as the server holds it."""

    number: int
    timestamp_s: float  # time.monotonic() at publish
    jpeg: bytes
    scene_s: float | None = None  # time.monotonic() at which the scene shown was current


class MjpegServer:
    """Serve published frames over HTTP MJPEG; `close()` or use as a context manager.

    `port=0` picks a free port (see `.port` / `.stream_url`). `client_timeout_s`
    bounds every socket write, so a client that stops reading is dropped instead
    of holding a thread forever.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        jpeg_quality: int = 90,
        truth_history: int = 256,
        client_timeout_s: float = 5.0,
        on_demand: bool = False,
    ) -> None:
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {jpeg_quality}")
        if truth_history < 1:
            raise ValueError(f"truth_history must be >= 1, got {truth_history}")
        self._jpeg_quality = int(jpeg_quality)
        self._truth_history = truth_history
        self._cond = threading.Condition()
        self._latest: PublishedFrame | None = None
        self._truths: OrderedDict[int, Any] = OrderedDict()
        self._next_number = 0
        self._closing = False
        self._clients: set[threading.Thread] = set()  # stream clients' handlers
        self.on_demand = on_demand
        self._asked = 0  # demands made, numbered from 1
        self._picture_asked = 0  # the number of the last demand for a new frame (not only the truth)
        self._answered = 0  # every demand up to this number is answered
        try:
            self._httpd = _Httpd((host, port), _Handler, self, client_timeout_s)
        except OSError as exc:
            raise OSError(exc.errno, f"MJPEG server cannot bind {host}:{port}: {exc.strerror}") from exc
        self._thread = threading.Thread(
            target=self._httpd.serve_forever, kwargs={"poll_interval": 0.1}, name="mjpeg-server", daemon=True
        )
        self._thread.start()
        log.info("MJPEG server on %s", self.stream_url)

    @property
    def host(self) -> str:
        return str(self._httpd.server_address[0])

    @property
    def port(self) -> int:
        return int(self._httpd.server_address[1])

    @property
    def stream_url(self) -> str:
        return f"http://{self.host}:{self.port}/stream.mjpg"

    @property
    def frames_published(self) -> int:
        return self._next_number

    @property
    def stream_clients(self) -> int:
        """Stream clients connected now (each is sent every frame it can take)."""
        with self._cond:
            return len(self._clients)

    def publish(
        self, image_rgb: np.ndarray, truth: Any = None, scene_s: float | None = None, answers: int = 0
    ) -> int:
        """Encode an RGB uint8 (H, W, 3) image as the newest frame; returns its frame number.

        `truth` (anything JSON-serialisable) is served at `/truth.json` beside it; `scene_s` (this host's
        time.monotonic() when the scene shown was current) goes with the frame's stream part. `answers`:
        every demand up to this number (`asked()`, read before the scene shown) is answered by it.
        """
        jpeg = encode_jpeg(image_rgb, self._jpeg_quality)
        truth_json = json.dumps(truth) if truth is not None else None  # fail here, not in a handler
        with self._cond:
            number = self._next_number
            self._next_number += 1
            self._latest = PublishedFrame(number, time.monotonic(), jpeg, scene_s)
            if truth_json is not None:
                self._truths[number] = truth_json
                while len(self._truths) > self._truth_history:
                    self._truths.popitem(last=False)
            self._answered = max(self._answered, answers)
            self._cond.notify_all()
        return number

    # ------------------------------------------------------------------ demands
    def asked(self) -> tuple[int, bool]:
        """(the last demand's number if one is unanswered, else 0; whether an unanswered one wants a new
        frame, not only the truth of the latest one). The publisher reads this before it reads the
        scene it answers with."""
        with self._cond:
            if self._asked <= self._answered:
                return 0, False
            return self._asked, self._picture_asked > self._answered

    def answer(self, upto: int) -> None:
        """Every demand up to `upto` is answered by the latest frame (its scene has not changed since);
        while a demand for a new frame is unanswered, nothing is: only a frame published answers that, and
        the demands before it with it."""
        with self._cond:
            if self._picture_asked <= self._answered < upto:
                self._answered = upto
                self._cond.notify_all()

    def wait_asked(self, timeout_s: float) -> bool:
        """Until a demand is unanswered (True), or `timeout_s` passes."""
        asked = lambda: self._closing or self._asked > self._answered  # noqa: E731
        with self._cond:
            return self._cond.wait_for(asked, timeout_s) and not self._closing

    def ask(self, new_frame: bool, timeout_s: float) -> PublishedFrame | None:
        """A demand: the latest frame once it answers this demand (on demand), or the first frame published
        after it (otherwise: the publisher keeps its own pace); None after `timeout_s`."""
        with self._cond:
            if not self.on_demand:  # a publisher at its own pace keeps no count of demands
                return self._newer(-1 if self._latest is None else self._latest.number, timeout_s)
            self._asked += 1
            number = self._asked
            if new_frame:
                self._picture_asked = number
            self._cond.notify_all()
            answered = lambda: self._closing or (self._answered >= number and self._latest is not None)  # noqa: E731
            return self._latest if self._cond.wait_for(answered, timeout_s) and not self._closing else None

    def latest(self) -> PublishedFrame | None:
        with self._cond:
            return self._latest

    def wait_newer(self, after_number: int, timeout_s: float) -> PublishedFrame | None:
        """The latest frame if its number is above `after_number`, waiting up to `timeout_s`."""
        with self._cond:
            return self._newer(after_number, timeout_s)

    def _newer(self, after_number: int, timeout_s: float) -> PublishedFrame | None:
        """`wait_newer`, holding `_cond`."""
        newer = lambda: self._closing or (self._latest is not None and self._latest.number > after_number)  # noqa: E731
        return self._latest if self._cond.wait_for(newer, timeout_s) and not self._closing else None

    def truth_json(self, number: int | None) -> str | None:
        """The truth JSON of frame `number` (the latest frame when None)."""
        with self._cond:
            if number is None:
                if self._latest is None or self._latest.number not in self._truths:
                    return None
                number = self._latest.number
            body = self._truths.get(number)
        return None if body is None else f'{{"frame_number": {number}, "truth": {body}}}'

    @property
    def closing(self) -> bool:
        return self._closing

    def _register(self, thread: threading.Thread, add: bool) -> None:
        """A stream client's handler, come or gone."""
        with self._cond:
            (self._clients.add if add else self._clients.discard)(thread)

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop serving, end every stream and free the port (idempotent)."""
        with self._cond:
            if self._closing:
                return
            self._closing = True
            self._cond.notify_all()
            clients = list(self._clients)
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join(timeout_s)
        for thread in clients:
            thread.join(timeout_s)
        log.info("MJPEG server on port %d closed after %d frames", self.port, self._next_number)

    def __enter__(self) -> MjpegServer:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class _Httpd(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 256  # the listen backlog: many viewers connecting at once all get in (was 5)

    def __init__(
        self, address: tuple[str, int], handler: type, owner: MjpegServer, client_timeout_s: float
    ) -> None:
        self.owner = owner
        self.client_timeout_s = client_timeout_s
        super().__init__(address, handler)


class _Handler(BaseHTTPRequestHandler):
    server: _Httpd
    protocol_version = "HTTP/1.0"

    def setup(self) -> None:
        self.timeout = self.server.client_timeout_s  # bounds every read and write on this socket
        super().setup()

    def log_message(self, format: str, *args: Any) -> None:
        log.debug("%s %s", self.address_string(), format % args)

    def do_GET(self) -> None:
        url = urlsplit(self.path)
        try:
            if url.path == "/stream.mjpg":
                self._stream()
            elif url.path == "/frame.jpg":
                self._frame(url.query)
            elif url.path == "/truth.json":
                self._truth(url.query)
            else:
                self.send_error(404, f"no such path {url.path}; try /stream.mjpg, /frame.jpg, /truth.json")
        except (TimeoutError, BrokenPipeError, ConnectionResetError) as exc:
            log.debug("client %s left: %s", self.address_string(), exc)

    def _send_body(self, content_type: str, body: bytes, headers: dict[str, str] | None = None) -> None:
        self.send_response(200)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        for key, value in (headers or {}).items():
            self.send_header(key, value)
        self.end_headers()
        self.wfile.write(body)

    def _frame(self, query: str) -> None:
        owner = self.server.owner
        fresh = owner.on_demand or parse_qs(query).get("fresh", ["0"])[0] not in ("", "0")
        frame = owner.ask(True, self.server.client_timeout_s) if fresh else owner.latest()
        if frame is None:
            if fresh:
                self.send_error(504, f"no frame within {self.server.client_timeout_s:g} s")
            else:
                self.send_error(503, "no frame published yet")
            return
        headers = {"X-Frame-Number": str(frame.number)}
        if frame.scene_s is not None:
            headers[SCENE_STAMP_HEADER] = format_scene_stamp(frame.scene_s)
        self._send_body("image/jpeg", frame.jpeg, headers)

    def _truth(self, query: str) -> None:
        values = parse_qs(query).get("frame")
        try:
            number = int(values[0]) if values else None
        except ValueError:
            self.send_error(400, f"frame must be an integer, got {values[0]!r}")
            return
        owner = self.server.owner
        if number is None and owner.on_demand:
            owner.ask(False, TRUTH_WAIT_S)  # the truth of now; else the latest there is, as before
        body = owner.truth_json(number)
        if body is None:
            self.send_error(404, f"no truth for frame {number if number is not None else '(latest)'}")
            return
        self._send_body("application/json", body.encode())

    def _stream(self) -> None:
        owner = self.server.owner
        self.send_response(200)
        self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Connection", "close")
        self.end_headers()
        me = threading.current_thread()
        owner._register(me, add=True)
        try:
            last = -1
            while not owner.closing:
                frame = owner.wait_newer(last, _WAKE_INTERVAL_S)
                if frame is None:
                    continue
                stamp = (
                    ""
                    if frame.scene_s is None
                    else f"{SCENE_STAMP_HEADER}: {format_scene_stamp(frame.scene_s)}\r\n"
                )
                header = (
                    f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(frame.jpeg)}\r\n"
                    f"X-Frame-Number: {frame.number}\r\n{stamp}\r\n"
                ).encode()
                self.wfile.write(header + frame.jpeg + b"\r\n")
                self.wfile.flush()
                last = frame.number
        finally:
            owner._register(me, add=False)
