"""The measuring behind `dronectl bench console`: the console as an operator sees it, in a real browser.

One console (`controller.console.run.open_console`) on the mission's vehicle, one page in Debian's
headless Chromium (`controller.benchmarks.browser`):

- **video**: for `video_s` seconds with the vehicle hovering, the page's own count of frames drawn
  (frames per second) and, per frame, the camera-to-page latency: the page's clock when the frame was
  drawn on the canvas minus the frame's arrival in the console's process (`Frame.timestamp_s` as Unix
  time; the page's `performance.timeOrigin + performance.now()`; one machine, one clock);
- **Hold**: `holds` times, an instruction is typed and, once the loop is flying it (its first step
  drawn, then a random 0.05-0.5 s more), the Hold button is clicked; the latency is from the page's
  clock at the click to the first telemetry sample (polled every 10 ms from the vehicle) in HOLD mode.
  Each instruction names the target in view farthest from the image centre (per the simulator's truth),
  so that the Hold interrupts a loop with a long way to fly.
"""

from __future__ import annotations

import random
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from controller.benchmarks.browser import open_browser, until
from controller.console.run import ConsoleOptions, open_console
from controller.missions.schema import Mission
from flight.types import FlightMode

OFFBOARD = FlightMode.OFFBOARD

POLL_S = 0.01
STEPS_JS = "window.consoleStats.steps"


@dataclass(frozen=True)
class ConsoleBenchSettings:
    mission: Mission
    out_dir: Path
    video_s: float = 10.0
    holds: int = 10
    fps: float = 20.0
    seed: int = 1


@dataclass
class ConsoleBenchResult:
    vehicle: str
    frame_px: list[int]
    video_s: float
    page_frames: int
    page_fps: float
    latency_ms: dict[str, float]
    hold_s: list[float] = field(default_factory=list)
    """Per Hold: the click (page clock) to the first telemetry sample in HOLD mode, seconds."""
    hold_to_thread_s: list[float] = field(default_factory=list)
    """Per Hold: the click to its command thread starting (page, WebSocket, server), seconds."""
    hold_call_s: list[float] = field(default_factory=list)
    """Per Hold: the session's `hold()` call, from its start to its return (HOLD confirmed), seconds."""
    hold_summary: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _quantiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {}
    ordered = sorted(values)

    def q(p: float) -> float:
        return ordered[min(len(ordered) - 1, max(0, round(p * (len(ordered) - 1))))]

    return {
        "n": len(values), "p50": q(0.5), "p95": q(0.95), "max": ordered[-1], "mean": statistics.fmean(values)
    }  # fmt: skip


def run_console_bench(settings: ConsoleBenchSettings) -> ConsoleBenchResult:
    """Open the console and a page, measure the video, take off, measure `holds` Holds."""
    rng = random.Random(settings.seed)
    options = ConsoleOptions(settings.mission, settings.out_dir, fps=settings.fps)
    with open_console(options) as console, open_browser() as browser:
        session, pilot = console.session, console.pilot
        page = browser.new_page()
        page.goto(console.url)
        until("the first frames", lambda: page.evaluate("window.consoleStats.frames") >= 5, 60)
        page.click("#btn-takeoff")
        until("airborne and holding", lambda: session.phase.value == "holding", 180)
        time.sleep(1.0)
        page.evaluate("window.consoleStats.frames = 0; window.consoleStats.firstFrameMs = null; "
                      "window.consoleStats.latencyMs = [];")  # fmt: skip
        time.sleep(settings.video_s)
        stats = page.evaluate("window.consoleStats")
        span_s = (stats["lastFrameMs"] - stats["firstFrameMs"]) / 1000.0 if stats["frames"] > 1 else 0.0
        frame = console.tap.latest()
        result = ConsoleBenchResult(
            vehicle=settings.mission.vehicle,
            frame_px=[frame.width, frame.height] if frame is not None else [],
            video_s=settings.video_s,
            page_frames=stats["frames"],
            page_fps=(stats["frames"] - 1) / span_s if span_s > 0 else 0.0,
            latency_ms=_quantiles([float(v) for v in stats["latencyMs"]]),
        )
        for i in range(settings.holds):
            steps_before = page.evaluate(STEPS_JS)
            page.fill("#instruction", f"centre the {_farthest_kind(session)}")
            page.press("#instruction", "Enter")
            try:
                until("the loop flying", lambda b=steps_before: page.evaluate(STEPS_JS) > b, 30)
            except TimeoutError:
                said = page.evaluate("window.consoleStats.messages.slice(-1)")
                result.notes.append(f"hold {i + 1}: the loop did not start ({said}); skipped")
                continue
            time.sleep(rng.uniform(0.05, 0.5))
            if session.phase.value != "centring" or session.vehicle.telemetry().flight_mode is not OFFBOARD:
                result.notes.append(f"hold {i + 1}: the loop had ended before the click; skipped")
                continue
            page.click("#btn-hold")
            seen = _hold_seen(session, 10.0)
            record = pilot.command_log[-1]
            if record.get("pressed_s") is not None:
                result.hold_s.append(round(seen - record["pressed_s"], 4))
                result.hold_to_thread_s.append(round(record["started_s"] - record["pressed_s"], 4))
                result.hold_call_s.append(round(record.get("done_s", seen) - record["started_s"], 4))
            until("the loop stopped", lambda: not pilot.busy, 30)
        result.hold_summary = _quantiles(result.hold_s)
        return result


def _farthest_kind(session: Any) -> str:
    """The kind of the target in view farthest from the image centre, per the simulator's truth (the
    benchmark's choice of words only, so that the loop has a long way to fly when Hold is clicked)."""
    truth = session.kit.targets_truth() if session.kit.targets_truth is not None else None
    seen = [t for t in truth or [] if t.offset_px is not None and t.kind]
    if not seen:
        return "gauge"
    return max(seen, key=lambda t: max(abs(t.offset_px[0]), abs(t.offset_px[1]))).kind


def _hold_seen(session: Any, timeout_s: float) -> float:
    """The Unix time of the first telemetry sample in HOLD mode, polled every `POLL_S`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if session.vehicle.telemetry().flight_mode is FlightMode.HOLD:
                return time.time()
        except Exception:  # a telemetry read that failed: the next poll
            pass
        time.sleep(POLL_S)
    raise TimeoutError(f"no HOLD mode in telemetry within {timeout_s:g} s of the click")
