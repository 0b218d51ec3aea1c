"""`CameraTap`: one reader of a camera whose frames feed both the centring loop and a live view.

A camera hands each frame to one reader (`Camera.read()` returns the newest frame *not returned
before*), so a second reader, a console showing the video, would take frames from the loop. The tap
reads the camera in a thread of its own, keeps the newest frame, and serves it twice: `read()` keeps
the `Camera` contract for the loop (the newest frame not returned to the loop before, waiting at
most `timeout_s`), and every listener is called with each new frame as it arrives (the live view).
A simulated camera renders on each read, so the tap reads it at most `max_fps` times per second.

The tap also says how the video is doing (`silent_s`: seconds since the last frame) and passes the
camera's own failures through: a stream that ended, or one closed, raises in `read()` as it would
have raised from the camera.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from perception.camera import Camera
from perception.errors import CameraError, CameraTimeoutError
from perception.newest_frame import NewestFrame
from perception.types import Frame

log = logging.getLogger(__name__)

FrameListener = Callable[[Frame], None]

READ_TIMEOUT_S = 0.5
"""How long the tap's reader waits on the camera before it looks at its stop flag again."""


class CameraTap(Camera):
    """Reads `camera` in its own thread; `read()` for one consumer, `add_listener` for any others.

    `max_fps`: the most frames per second the reader asks for (None: as fast as they come; a
    stream camera paces itself). The tap owns the camera: `close()` closes it."""

    def __init__(self, camera: Camera, max_fps: float | None = None, name: str | None = None) -> None:
        if max_fps is not None and not max_fps > 0:
            raise ValueError(f"max_fps must be > 0, got {max_fps!r}")
        self.camera = camera
        self.name = name or getattr(camera, "name", "camera")
        self._period_s = 0.0 if max_fps is None else 1.0 / max_fps
        self._frames = NewestFrame(self.name)
        self._cond = self._frames.cond
        self._listeners: list[FrameListener] = []
        self._stop = threading.Event()
        self._last_frame_monotonic = time.monotonic()
        self.frames = 0
        self._thread = threading.Thread(target=self._run, name=f"camera-tap {self.name}", daemon=True)
        self._thread.start()

    # --- the reader ---------------------------------------------------------------------------
    def _run(self) -> None:
        next_s = time.monotonic()
        while not self._stop.is_set():
            if self._period_s:
                wait_s = next_s - time.monotonic()
                if wait_s > 0 and self._stop.wait(wait_s):
                    return
                next_s = max(next_s + self._period_s, time.monotonic())
            try:
                frame = self.camera.read(READ_TIMEOUT_S)
            except CameraTimeoutError:
                continue  # `silent_s` says it; the loop's own read times out on its own deadline
            except CameraError as exc:  # ended, closed: for good
                self._fail(exc)
                return
            except Exception as exc:  # a camera that breaks in a way of its own: said, not fatal to us
                log.exception("camera tap %s: the camera failed", self.name)
                self._fail(CameraError(self.name, f"{type(exc).__name__}: {exc}"))
                return
            with self._cond:
                self._frames.put(frame)
                self._last_frame_monotonic = time.monotonic()
                self.frames += 1
                listeners = list(self._listeners)
            for listener in listeners:
                try:
                    listener(frame)
                except Exception:  # a view that fails never costs the loop its frames
                    log.exception("camera tap %s: a frame listener failed", self.name)

    def _fail(self, error: CameraError) -> None:
        self._frames.end(error)
        log.warning("camera tap %s: %s", self.name, error)

    # --- consumers ----------------------------------------------------------------------------
    def add_listener(self, listener: FrameListener) -> None:
        """Call `listener(frame)` from the reader thread with every new frame (keep it quick)."""
        with self._cond:
            self._listeners.append(listener)

    def remove_listener(self, listener: FrameListener) -> None:
        with self._cond:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def latest(self) -> Frame | None:
        """The newest frame, whoever has seen it (None before the first)."""
        with self._cond:
            return self._frames.latest

    def silent_s(self) -> float:
        """Seconds since the last frame arrived (since the tap started, before the first)."""
        with self._cond:
            return time.monotonic() - self._last_frame_monotonic

    @property
    def failure(self) -> CameraError | None:
        """The camera's lasting failure (stream ended, closed), None while it delivers."""
        return self._frames.ended

    def read(self, timeout_s: float | None = None) -> Frame:
        """The newest frame not returned by `read()` before; `CameraTimeoutError` after `timeout_s`."""
        timeout = READ_TIMEOUT_S * 4 if timeout_s is None else timeout_s
        return self._frames.take(timeout, lambda: "no frame from the camera")

    def close(self) -> None:
        """Stop the reader and close the camera (idempotent)."""
        if not self._frames.close():
            return
        self._stop.set()
        self._thread.join(READ_TIMEOUT_S * 4)
        self.camera.close()
