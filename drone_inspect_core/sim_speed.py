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
