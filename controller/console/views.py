"""What the console's page is sent, as JSON-able dicts: a loop step, the detections, the telemetry.

Plain functions of the loop's records and the vehicle's telemetry, so the page shows exactly what the
loop saw and decided (the step's own frame number, its detections, the named one, the nine distances
and the chosen move) and nothing computed a second time.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

from controller.planning.actions import ALL_ACTIONS
from controller.planning.grounding import TargetQuery
from controller.planning.loop_records import StepRecord
from flight.types import Telemetry
from perception.types import Detection, Frame

ACTION_NAMES: tuple[str, ...] = tuple(action.name for action in ALL_ACTIONS)
"""The nine moves in the planner's order (index = 3·x + z), as the page labels its bars."""


def _round(values: Sequence[float], digits: int = 1) -> list[float]:
    return [round(float(v), digits) for v in values]


def _finite(value: float | None, digits: int = 3) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def detection_view(detection: Detection, named: bool = False) -> dict[str, Any]:
    """One detection: its box, centre, kind, trim colour and score; `named`: the instruction's target."""
    return {
        "bbox_px": _round(detection.bbox_px),
        "centre_px": _round(detection.centre_px),
        "kind": detection.kind,
        "colour": detection.attribute,
        "score": round(float(detection.confidence), 3),
        "named": named,
    }


def detections_view(detections: Sequence[Detection], named: Detection | None) -> list[dict[str, Any]]:
    """Every detection, strongest first, the named one (the same object the loop chose) marked."""
    return [detection_view(d, named is not None and d is named) for d in detections]


def wall_time_of(frame: Frame) -> float:
    """The frame's arrival (`Frame.timestamp_s`, monotonic) as Unix time in seconds: the page's clock
    (`performance.timeOrigin + performance.now()`) on the same machine compares with it."""
    return time.time() - (time.monotonic() - frame.timestamp_s)


def frame_header(frame: Frame) -> dict[str, Any]:
    """What goes with a video frame to the page: its number, size and arrival time (Unix ms)."""
    return {
        "n": frame.frame_number,
        "w": frame.width,
        "h": frame.height,
        "t_ms": round(wall_time_of(frame) * 1000.0, 1),
    }


def step_view(
    step: StepRecord, instruction: str, target: TargetQuery | None, epsilon_px: float, number: int
) -> dict[str, Any]:
    """One step of the loop as the page draws it over the video and in the planner's bars.

    `number`: which instruction of the session (1, 2, ...) this step belongs to."""
    distances = None if step.distances is None else [_finite(d, 4) for d in step.distances]
    return {
        "type": "step",
        "instruction": instruction,
        "instruction_number": number,
        "target": None if target is None else target.describe(),
        "index": step.index,
        "frame": step.frame.frame_number,
        "frame_size": [step.frame.width, step.frame.height],
        "event": step.event.value,
        "centred": step.centred,
        "epsilon_px": epsilon_px,
        "stop_threshold_px": step.stop_threshold_px,
        "offset_px": None if step.offset_px is None else _round(step.offset_px),
        "detections": detections_view(step.detections, step.detection),
        "distances": distances,
        "action": None if step.action is None else step.action.index,
        "action_name": None if step.action is None else step.action.name,
        "move_m": None if step.move_m is None else _round(step.move_m, 3),
    }


def telemetry_view(telemetry: Telemetry | None, setpoint_age_s: float | None, link: str) -> dict[str, Any]:
    """The vehicle's state for the page: mode, armed, in the air, altitude above home, battery where
    the vehicle reports one, the age of the last velocity setpoint, and the link ("ok" / "lost")."""
    if telemetry is None:
        return {"type": "telemetry", "link": link}
    return {
        "type": "telemetry",
        "link": link,
        "mode": telemetry.flight_mode.value,
        "armed": telemetry.armed,
        "in_air": telemetry.in_air,
        "altitude_m": _finite(-telemetry.position_ned.down_m, 2),
        "speed_m_s": _finite(telemetry.velocity_ned.speed_m_s, 2),
        "yaw_deg": _finite(telemetry.attitude.yaw_deg, 1),
        "battery_percent": _finite(telemetry.battery_remaining_percent, 1),
        "setpoint_age_s": _finite(setpoint_age_s, 2),
    }
