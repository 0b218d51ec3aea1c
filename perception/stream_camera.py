"""A camera on OpenCV's VideoCapture that always hands back the newest frame.

Sources: an HTTP MJPEG URL (the simulated vehicle's stream, IP cameras), RTSP /
UDP / RTMP / SRT URLs (what drone video bridges serve), a device index (a USB or
HDMI capture card) or a video file (played back at its own frame rate, as if
live). See docs/perception.md for pointing it at a real drone.

Why a reader thread: VideoCapture decodes frames in order, so a program that
reads only when it needs a frame gets one that waited in FFmpeg's and the
socket's buffers, seconds old after a slow control step. The thread here reads
continuously and keeps only the latest frame; `read()` returns a frame newer than
the one it returned last, or raises `CameraTimeoutError` when none comes in time.

A live source that drops (video links do) is reopened by the reader until it
comes back or the camera is closed; meanwhile `read()` raises `CameraTimeoutError`
saying so. A video file ends with `CameraStreamEndedError`.

A simulator's own stream, read with `scene_stamps=True`, is read part by part
(`perception.mjpeg_http`, each JPEG still decoded by OpenCV) so that each frame
keeps the scene stamp its render process sent (`Frame.scene_s`); FFmpeg's reader
drops it. With `on_demand=True` as well, the simulator is asked for one picture per
`read()` (`MjpegPullCapture`): its render process draws only the pictures read.

Every wait is bounded: opening (OpenCV's CAP_PROP_OPEN_TIMEOUT_MSEC plus a join
timeout, since some backends ignore it), each decode (CAP_PROP_READ_TIMEOUT_MSEC),
`read()` and `close()`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2

from perception.camera import Camera
from perception.errors import CameraOpenError, CameraStreamEndedError
from perception.mjpeg_http import MjpegHttpCapture, MjpegPullCapture
from perception.newest_frame import NewestFrame
from perception.types import Frame

log = logging.getLogger(__name__)

_RECONNECT_BACKOFF_S = 0.5
_WANTED_POLL_S = 0.2  # on demand, how often the idle reader looks at the stop flag
_OPEN_HINT = (
    "OpenCV could not open it (refused connection, unreachable host, wrong path, no such device "
    "or unsupported format); check it with `ffprobe <source>`"
)


def describe_source(source: str | int) -> str:
    """How a source is named in messages."""
    return f"device {source}" if isinstance(source, int) else repr(source)


class StreamCamera(Camera):
    """Frames from a URL, a device index or a video file, newest first.

    `timeout_s`: `read()`'s default wait for a new frame, and how long the reader
    lets one decode block before it declares the stream dropped.
    `open_timeout_s`: the limit for connecting and reading the stream header.
    `realtime_file`: pace a video file at its frame rate (True) or decode it as fast
    as possible (False; then `read()` skips whatever the reader outran).
    `reconnect`: reopen a live source after it drops (False: `CameraStreamEndedError`).
    `scene_stamps`: the source is an http:// MJPEG stream of a simulator on this host; its parts'
    scene stamps are this host's clock and become `Frame.scene_s` (see `drone_inspect_core.video_stamps`).
    `on_demand` (with `scene_stamps`): no reading between `read()`s; each asks the simulator for a picture
    drawn after it began, so nothing is drawn, sent or decoded that no one reads.
    `source_alive`: whether the process serving the stream still runs (a simulator the caller started);
    a stream that drops once it has exited ends at once (`CameraStreamEndedError`) instead of `read()`
    waiting out its timeout for a reconnect that cannot come.
    """

    def __init__(
        self,
        source: str | int,
        timeout_s: float = 2.0,
        open_timeout_s: float = 5.0,
        realtime_file: bool = True,
        reconnect: bool = True,
        scene_stamps: bool = False,
        source_alive: Callable[[], bool] | None = None,
        on_demand: bool = False,
    ) -> None:
        if timeout_s <= 0 or open_timeout_s <= 0:
            raise ValueError(
                f"timeouts must be > 0, got timeout_s={timeout_s}, open_timeout_s={open_timeout_s}"
            )
        if isinstance(source, str) and source.isdigit():
            source = int(source)
        self.source = source
        self.name = describe_source(source)
        self.timeout_s = timeout_s
        self._is_file = isinstance(source, str) and "://" not in source
        if scene_stamps and not (isinstance(source, str) and source.startswith("http://")):
            raise ValueError(f"scene stamps come only with an http:// MJPEG stream, not {self.name}")
        if on_demand and not scene_stamps:
            raise ValueError("pictures on demand come only from a simulator's stream read with scene stamps")
        self._scene_stamps = scene_stamps
        self._on_demand = on_demand
        self._wanted = threading.Event()  # on demand: a read() waits for a picture
        self._source_alive = source_alive
        self._open_error: str | None = None
        if self._is_file and not Path(str(source)).is_file():
            raise CameraOpenError(self.name, "no such video file")
        live_file = self._is_file and str(source).lower().endswith(".sdp")  # an RTP session description
        self._pace = self._is_file and realtime_file and not live_file
        self._reconnect = reconnect and (live_file or not self._is_file)
        self._open_timeout_s = open_timeout_s
        self._frames = NewestFrame(self.name)
        self._cond = self._frames.cond
        self._stop = threading.Event()
        self._opened = threading.Event()
        self._open_failed = False
        self._dropped: str | None = None  # why the reader is reconnecting
        self.frames_received = 0
        self.frames_returned = 0
        self.reconnects = 0
        self._thread = threading.Thread(target=self._run, name=f"stream-camera {self.name}", daemon=True)
        self._thread.start()
        if not self._opened.wait(open_timeout_s + 1.0):
            self._stop.set()
            raise CameraOpenError(self.name, f"did not open within {open_timeout_s:.3g} s; {_OPEN_HINT}")
        if self._open_failed:
            raise CameraOpenError(self.name, self._open_error or _OPEN_HINT)
        log.info("camera %s open", self.name)

    def _source_gone(self) -> bool:
        return self._source_alive is not None and not self._source_alive()

    def _capture(self) -> cv2.VideoCapture | MjpegHttpCapture | MjpegPullCapture:
        if self._on_demand:
            return MjpegPullCapture(str(self.source), self._open_timeout_s, self.timeout_s)
        if self._scene_stamps:
            return MjpegHttpCapture(str(self.source), self._open_timeout_s, self.timeout_s)
        if isinstance(self.source, int):
            return cv2.VideoCapture(self.source, cv2.CAP_ANY)
        params = [
            cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
            int(self._open_timeout_s * 1000),
            cv2.CAP_PROP_READ_TIMEOUT_MSEC,
            int(self.timeout_s * 1000),
        ]
        return cv2.VideoCapture(self.source, cv2.CAP_FFMPEG, params)

    def _run(self) -> None:
        """Reader thread: open, decode into `_frames`, and reconnect after a drop (live sources)."""
        number = 0
        try:
            while not self._stop.is_set():
                cap = self._capture()
                try:
                    if not cap.isOpened():
                        if not self._opened.is_set():  # the first open: the constructor reports it
                            self._open_failed = True
                            if isinstance(cap, (MjpegHttpCapture, MjpegPullCapture)):
                                self._open_error = f"{cap.error}; is the simulator's stream up?"
                            return
                        if self._source_gone():
                            self._frames.end(CameraStreamEndedError(self.name, "its source has exited"))
                            return
                        self._stop.wait(_RECONNECT_BACKOFF_S)
                        continue
                    if self._opened.is_set():
                        self.reconnects += 1
                        log.info("camera %s reconnected", self.name)
                    self._opened.set()
                    with self._cond:
                        self._dropped = None
                    number = self._decode(cap, number)
                finally:
                    cap.release()
                if self._stop.is_set():
                    return
                what = "end of file" if self._is_file else "stream dropped or stalled"
                reason = f"{what} after {number} frames"
                with self._cond:
                    if self._source_gone():  # nothing will serve it again: say so now, not at a timeout
                        self._frames.end(
                            CameraStreamEndedError(self.name, f"{reason}; its source has exited")
                        )
                        return
                    if self._reconnect:
                        self._dropped = f"{reason}; reconnecting"
                    else:
                        self._frames.end(CameraStreamEndedError(self.name, reason))
                if not self._reconnect:
                    return
                log.warning("camera %s: %s; reconnecting", self.name, reason)
        finally:
            self._opened.set()

    def _decode(self, cap: cv2.VideoCapture | MjpegHttpCapture | MjpegPullCapture, number: int) -> int:
        """Decode frames until the source fails or `close()` (on demand: one per `read()` waiting for one);
        returns the next frame number."""
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        period_s = 1.0 / fps if self._pace and 0.0 < fps < 1000.0 else 0.0
        start, first = time.monotonic(), number
        while not self._stop.is_set():
            if self._on_demand:
                if not self._wanted.wait(_WANTED_POLL_S) or self._stop.is_set():
                    continue
                self._wanted.clear()
            ok, bgr = cap.read()
            if not ok or bgr is None:
                break
            scene_s = cap.scene_s if isinstance(cap, (MjpegHttpCapture, MjpegPullCapture)) else None
            frame = Frame(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), time.monotonic(), number, scene_s)
            number += 1
            with self._cond:
                self._frames.put(frame)
                self.frames_received = number
            if period_s:
                self._stop.wait(max(0.0, start + (number - first) * period_s - time.monotonic()))
        return number

    def read(self, timeout_s: float | None = None) -> Frame:
        """The newest frame received since the last `read()` (on demand: the picture this read asked for);
        waits up to `timeout_s`."""
        timeout = self.timeout_s if timeout_s is None else timeout_s
        if self._on_demand:  # the picture asked for now: not one a read that timed out asked for
            self._frames.pass_over()
            self._wanted.set()
        with self._cond:
            frame = self._frames.take(timeout, lambda: self._dropped or "stream stalled or frozen")
            self.frames_returned += 1
            return frame

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop the reader; it releases the capture as soon as its current decode returns."""
        if not self._frames.close():
            return
        self._stop.set()
        self._wanted.set()  # an idle reader on demand wakes at once
        self._thread.join(timeout_s)
        if self._thread.is_alive():  # normal on a live stream with no new frame: it exits on its own
            log.debug("camera %s: reader still blocked in a decode; it exits when that returns", self.name)
