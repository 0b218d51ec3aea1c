"""A simulator's speed: simulated seconds per wall second, or "max" (as fast as it goes).

Shared by the simulated MAVLink vehicle (`sim_world.vehicle`), the mission files and the CLIs,
which must not import the simulator to check a number.
"""

from __future__ import annotations

import math
from typing import Literal

MAX_SPEED = "max"
SimSpeed = float | Literal["max"]
"""Simulated seconds per wall second, or "max": physics as fast as the loop thread steps it."""

OFF_REAL_TIME_FRESH_FRAME_S = 0.1
"""A simulator off real time: a picture taken "now" is the first frame whose scene stamp is at or after
now (`drone_inspect_core.video_stamps`), or from a camera that stamps nothing, the first that arrives
this long (wall time) after now. Render, JPEG and HTTP take a few tens of ms of wall time, more on a
loaded machine, which at ×8 or "max" are tenths of a simulated second: a frame arriving at once can show
the drone before it stopped (a flown collection once labelled such a frame 19 px from the truth)."""


def off_real_time(speed: SimSpeed | str | None) -> bool:
    """Whether a simulator at `speed` (None: a real vehicle, or no simulator) runs off real time."""
    return speed is not None and parse_sim_speed(speed) != 1.0


def parse_sim_speed(value: str | float) -> SimSpeed:
    """A speed from a CLI, mission or JSON value: a number in [0.05, 100] or "max" (ValueError otherwise)."""
    if isinstance(value, str):
        if value.strip().lower() == MAX_SPEED:
            return MAX_SPEED
        try:
            value = float(value)
        except ValueError:
            raise ValueError(f"speed must be a number or 'max', got {value!r}") from None
    speed = float(value)
    if not (math.isfinite(speed) and 0.05 <= speed <= 100.0):
        raise ValueError(f"speed must be in [0.05, 100] or 'max', got {speed:g}")
    return speed
