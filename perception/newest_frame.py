"""`NewestFrame`: the newest frame a reader thread got, handed to one consumer at most once.

A camera read in a thread of its own (`StreamCamera`, `CameraTap`) keeps only its newest frame; its
`read()` returns a frame newer than the one it returned last, or waits for one until a deadline. The
reader `put()`s each frame; `end(error)` says the source is gone for good (a stream that ended, a
camera that failed), and `take()` then raises that error once no untaken frame is left; `close()`
makes `take()` raise `CameraClosedError` at once.

`cond` is the slot's lock and condition (re-entrant): a reader keeping more state beside the frame
(counters, a reconnect's reason) holds it around both.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from perception.errors import CameraClosedError, CameraError, CameraTimeoutError
from perception.types import Frame


class NewestFrame:
    """The newest frame of a camera called `name`, taken by its one consumer."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.cond = threading.Condition()
        self.latest: Frame | None = None
        self._taken = -1  # the frame number `take()` returned last
        self._end: CameraError | None = None
        self._closed = False

    def put(self, frame: Frame) -> None:
        """The reader's newest frame (it replaces any untaken one)."""
        with self.cond:
            self.latest = frame
            self.cond.notify_all()

    def pass_over(self) -> None:
        """Count the newest frame as taken without taking it: `take()` then waits for a later one."""
        with self.cond:
            if self.latest is not None:
                self._taken = max(self._taken, self.latest.frame_number)

    def end(self, error: CameraError) -> None:
        """The source is gone for good: `take()` raises `error` once no untaken frame is left."""
        with self.cond:
            self._end = error
            self.cond.notify_all()

    @property
    def ended(self) -> CameraError | None:
        with self.cond:
            return self._end

    def close(self) -> bool:
        """`take()` raises `CameraClosedError` from now on; False if it was closed already."""
        with self.cond:
            if self._closed:
                return False
            self._closed = True
            self.cond.notify_all()
            return True

    def take(self, timeout_s: float, why_none: Callable[[], str]) -> Frame:
        """The newest frame not taken before, waiting up to `timeout_s`; then `CameraTimeoutError` with
        `why_none()` (called holding `cond`) as its reason."""
        deadline = time.monotonic() + timeout_s
        with self.cond:
            while True:
                if self._closed:
                    raise CameraClosedError(self.name, "read() after close()")
                latest = self.latest
                if latest is not None and latest.frame_number > self._taken:
                    self._taken = latest.frame_number
                    return latest
                if self._end is not None:
                    raise self._end
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise CameraTimeoutError(self.name, timeout_s, why_none())
                self.cond.wait(remaining)
