"""The scene stamp of a simulated camera's frames: when the scene a frame shows was current.

A simulator's render process draws the drone where the vehicle last wrote it and stamps the frame
with the `time.monotonic()` at which it read that pose; its MJPEG server sends the stamp as a header
of each part (`SCENE_STAMP_HEADER`), and a reader on the same host that was told to trust it
(`perception.stream_camera.StreamCamera(scene_stamps=True)`) hands it on as `Frame.scene_s`. CLOCK_MONOTONIC
is one clock for every process of a host, and only of that host: a stamp from another machine
means nothing here, so a reader trusts it only when asked to, for a simulator it started itself.
"""

from __future__ import annotations

import math

SCENE_STAMP_HEADER = "X-Scene-Monotonic"


def format_scene_stamp(scene_s: float) -> str:
    """The header value for a stamp (seconds of time.monotonic(), to the microsecond)."""
    return f"{scene_s:.6f}"


def parse_scene_stamp(value: str | None) -> float | None:
    """A stamp from a header value; None when absent or not a finite, non-negative number."""
    if value is None:
        return None
    try:
        stamp = float(value.strip())
    except ValueError:
        return None
    return stamp if math.isfinite(stamp) and stamp >= 0.0 else None
