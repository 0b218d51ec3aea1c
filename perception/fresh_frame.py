"""A picture taken now: the first frame that shows the scene as it was at or after a given moment.

A camera's newest frame can be older than the moment it is read: it was rendered (or exposed),
encoded, sent and decoded before it came into hand. A vehicle that has just stopped needs a frame
of where it stopped, not of where it was a moment before. Two ways to know:

- the source says when the scene it shows was current (`Frame.scene_s`: a simulator's render
  process stamps each frame with the time it read the pose it drew): the first frame stamped at or
  after the moment is exact, however slow the renderer or the machine;
- it does not (every real camera here): the first frame that *arrived* `margin_s` after the moment,
  a wall-time margin for the pipeline's latency (`drone_inspect_core.sim_speed.OFF_REAL_TIME_FRESH_FRAME_S`
  for a simulator off real time; 0 on a real vehicle, whose camera runs at the world's own pace).

Either wait is bounded: after `timeout_s` the newest frame is taken (a stream that is slow but alive).
"""

from __future__ import annotations

import time

from perception.camera import Camera
from perception.types import Frame


def is_fresh(frame: Frame, since_s: float, margin_s: float) -> bool:
    """Whether `frame` shows the scene at or after `since_s` (time.monotonic()): by its scene stamp when
    it has one, else by having arrived `margin_s` after `since_s`."""
    if frame.scene_s is not None:
        return frame.scene_s >= since_s
    return frame.timestamp_s >= since_s + margin_s


def read_fresh(camera: Camera, since_s: float, margin_s: float, timeout_s: float) -> Frame:
    """The camera's first frame that `is_fresh` for `since_s`, re-reading until `timeout_s` past the
    margin; then the newest frame read. Each read waits up to `timeout_s` (`CameraTimeoutError` when
    none comes: a stream that stopped is not a slow one)."""
    give_up_s = since_s + margin_s + timeout_s
    frame = camera.read(timeout_s)
    while not is_fresh(frame, since_s, margin_s) and time.monotonic() < give_up_s:
        frame = camera.read(timeout_s)
    return frame
