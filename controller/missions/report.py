"""The report folder of one flight: `report.json`, a trajectory plot, an annotated GIF (and a .tlog).

A flight centres one or more instructions (`controller.missions.session`). `ReportWriter` is told when
each instruction begins and ends and fed each step as the loop records it, and rewrites `report.json`
after every step (status `in_progress`), so a crash or Ctrl-C loses nothing that was recorded;
`finish()` (called from a `finally`) writes the final JSON, the plot and the GIF. Nothing in the folder
is needed to fly: it is for people and CI.

```
OUT/report.json       the mission, the flight's outcome and judgement, timing, and `instructions`: per
                      instruction its text, target, outcome, judgement, steps (counted as the budget
                      counts them), final offsets (truth, detector), wrong target, its step records
                      (`records`)
OUT/trajectory.png    the drone's path in the wall plane (one colour per instruction), and |offset| per step
OUT/camera.gif        each step's frame with bbox, ε box and the chosen action drawn on it
OUT/flight.tlog       MAVLink telemetry log (MAVLink flights only; see runner)
```
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure  # the object API: no pyplot state, no GUI backend
from PIL import Image

from controller.planning.loop_records import Outcome, StepEvent, StepRecord
from drone_inspect_core.files import claim_dir, release_claim, write_atomic, write_json_atomic
from perception.annotate import annotate
from perception.types import Detection

log = logging.getLogger(__name__)

REPORT_JSON = "report.json"
TRAJECTORY_PNG = "trajectory.png"
CAMERA_GIF = "camera.gif"
GIF_FRAME_MS = 600
RESERVE = ".reserve"
RESERVE_BYTES = 32 * 1024


def _pair(value: tuple[float, float] | None) -> list[float] | None:
    return None if value is None else [round(float(value[0]), 3), round(float(value[1]), 3)]


def detection_to_json(det: Detection) -> dict[str, Any]:
    """One detection as JSON: box, centre, confidence, kind and attribute."""
    return {
        "bbox_px": [round(float(x), 2) for x in det.bbox_px],
        "centre_px": _pair(det.centre_px),
        "confidence": round(float(det.confidence), 4),
        "kind": det.kind,
        "attribute": det.attribute,
    }


def step_to_json(step: StepRecord) -> dict[str, Any]:
    """One step as JSON (the frame itself goes to the GIF, not here)."""
    t = step.telemetry
    det = step.detection
    return {
        "index": step.index,
        "event": step.event.value,
        "frame_number": step.frame.frame_number,
        "vehicle_time_s": round(step.vehicle_time_s, 3),
        "detection": None if det is None else detection_to_json(det),
        "detections": [detection_to_json(d) for d in step.detections],
        "offset_px": _pair(step.offset_px),
        "truth_offset_px": _pair(step.truth_offset_px),
        "centred": step.centred,
        "stop_threshold_px": None if step.stop_threshold_px is None else round(step.stop_threshold_px, 3),
        "action": None if step.action is None else step.action.name,
        "distances": None if step.distances is None else [round(float(d), 6) for d in step.distances],
        "presence": None if step.presence is None else round(float(step.presence), 4),
        "pose": {
            "north_m": round(t.position_ned.north_m, 4),
            "east_m": round(t.position_ned.east_m, 4),
            "down_m": round(t.position_ned.down_m, 4),
            "yaw_deg": round(t.attitude.yaw_deg, 3),
        },
        "move": None
        if step.move is None
        else {
            "commanded_m": {"right_m": round(step.move_m[0], 4), "up_m": round(step.move_m[1], 4)}
            if step.move_m
            else None,
            "flown_m": {
                "right_m": round(step.move.displacement.right_m, 4),
                "up_m": round(-step.move.displacement.down_m, 4),
                "forward_m": round(step.move.displacement.forward_m, 4),
            },
            "duration_s": round(step.move.duration_s, 3),
            "settled": step.move.settled,
        },
        "timing_ms": {
            "read": round(step.timing.read_s * 1e3, 2),
            "detect": round(step.timing.detect_s * 1e3, 2),
            "plan": round(step.timing.plan_s * 1e3, 2),
            "move": round(step.timing.move_s * 1e3, 2),
            "overhead": round(step.timing.overhead_s * 1e3, 2),
        },
    }


def timing_summary(steps: list[StepRecord]) -> dict[str, float | None]:
    """Per-step overhead (everything but the move) in ms: mean, max; and the mean move time."""
    overhead = [s.timing.overhead_s * 1e3 for s in steps]
    moves = [s.timing.move_s * 1e3 for s in steps if s.move is not None]
    return {
        "steps_timed": len(overhead),
        "overhead_ms_mean": round(statistics.fmean(overhead), 2) if overhead else None,
        "overhead_ms_max": round(max(overhead), 2) if overhead else None,
        "move_ms_mean": round(statistics.fmean(moves), 2) if moves else None,
    }


def claim_report_dir(out_dir: str | Path) -> Path:
    """`out_dir` as this flight's own report folder (`drone_inspect_core.files.claim_dir`): new, or empty
    and claimed
    atomically; `OutputDirError` (one line) if it holds anything, another run holds it, or it cannot be
    written. A second flight there would truncate the first one's .tlog and replace its report."""
    return claim_dir(out_dir, "report folder")


def fresh_report_dir(base: str | Path) -> Path:
    """`base`, or `base-2`, `base-3`, ... : the first that does not exist yet (for default folder names)."""
    base = Path(base)
    candidate, n = base, 1
    while candidate.exists():
        n += 1
        candidate = base.with_name(f"{base.name}-{n}")
    return candidate


def hold_reserve(out_dir: Path, size_bytes: int = RESERVE_BYTES) -> None:
    """Put `size_bytes` of ballast (`.reserve`) in the report folder before the flight starts filling
    the disk; `ReportWriter.finish` frees it for the final report. Best effort: said, never raised."""
    reserve = Path(out_dir) / RESERVE
    try:
        with reserve.open("xb") as file:
            file.write(b"\0" * size_bytes)
    except OSError as exc:
        log.warning("no room for the report's reserve in %s: %s", out_dir, exc)
        with contextlib.suppress(OSError):
            reserve.unlink()


def write_setup_failure(out_dir: Path, mission: Any, error: BaseException) -> None:
    """The report of a mission that could not start (or was stopped before its flight's report began)."""
    how = (
        f"{type(error).__name__}: {error}"
        if not isinstance(error, KeyboardInterrupt)
        else f"interrupted ({error or 'SIGINT'})"
    )
    data = {
        "mission": mission.name,
        "tags": list(mission.tags),
        "planner": mission.planner,
        "vehicle": mission.vehicle,
        "camera": mission.camera,
        "mission_file": mission.model_dump(mode="json"),
        "status": "failed_to_start",
        "outcome": Outcome.ERROR.value,
        "passed": False,
        "error": how,
        "instructions": [],
        "files": {"report": REPORT_JSON, "trajectory": None, "gif": None, "tlog": None},
    }
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(OSError):
            (Path(out_dir) / RESERVE).unlink()
        write_json_atomic(Path(out_dir) / REPORT_JSON, data, indent=1)
        release_claim(out_dir)
    except OSError as exc:
        log.error("could not write the report of %s: %s", out_dir, exc)


@dataclass
class ReportWriter:
    """Writes one flight's report folder: `begin_instruction` / `add_step` after each step /
    `end_instruction` per instruction, `finish` once at the end.

    Recording never costs the flight: a write that fails (a full disk, a read-only or removed folder)
    is said once and stops the per-step rewrites; `finish` still tries the whole report, then one
    without its steps, and names what could not be written in `recording_errors`. A file is only
    ever replaced whole (`drone_inspect_core.files.write_atomic`): no `.tmp` or half-written file is left.
    So that the outcome fits even on a disk the flight filled (its .tlog, mostly), the writer holds
    `reserve_bytes` of ballast (`.reserve`) from the start and frees it before the final report.
    """

    out_dir: Path
    header: dict[str, Any]  # mission name, planner, ε, scene, ... (JSON-able)
    epsilon_px: float
    media: bool = True
    """Write the plot and the GIF (benchmarks turn this off: the JSON is what they need)."""
    instructions: list[dict[str, Any]] = field(default_factory=list)
    """Each instruction's entry as report.json holds it, its step records (JSON) under "records"."""
    steps: list[StepRecord] = field(default_factory=list)
    """Every step of the flight, in order (the GIF, the plot, the timing)."""
    step_instruction: list[int] = field(default_factory=list)
    """Each step's instruction (its index in `instructions`)."""
    recording_errors: list[str] = field(default_factory=list)
    """What could not be written, one line each (said once, also in the final report where it fits)."""
    reserve_bytes: int = RESERVE_BYTES

    def __post_init__(self) -> None:
        self.out_dir = Path(self.out_dir)
        self._steps_paused = False
        self._claim_held = True
        self._write({"status": "in_progress"})
        self._reserve = self.out_dir / RESERVE
        if not self._reserve.exists():
            hold_reserve(self.out_dir, self.reserve_bytes)

    @property
    def json_path(self) -> Path:
        return self.out_dir / REPORT_JSON

    def begin_instruction(self, entry: dict[str, Any]) -> None:
        """A new instruction begins (`entry`: what it asks; its steps follow)."""
        self.instructions.append({**entry, "status": "in_progress", "records": []})
        self._rewrite()

    def add_step(self, step: StepRecord) -> None:
        """A step of the current instruction (one is begun for a writer fed steps without one)."""
        if not self.instructions:
            self.begin_instruction({})
        self.steps.append(step)
        self.step_instruction.append(len(self.instructions) - 1)
        self.instructions[-1]["records"].append(step_to_json(step))
        self._rewrite()

    def end_instruction(self, summary: dict[str, Any]) -> None:
        """The current instruction ended: its outcome and judgement (`summary`)."""
        self.instructions[-1].update({**summary, "status": "finished"})
        self._rewrite()

    def _rewrite(self) -> None:
        if not self._steps_paused:
            self._steps_paused = not self._write({"status": "in_progress"})

    def _write(self, summary: dict[str, Any], with_steps: bool = True) -> bool:
        entries = self.instructions if with_steps else [{**e, "records": []} for e in self.instructions]
        data = {**self.header, **summary, "instructions": entries}
        try:
            write_json_atomic(self.json_path, data, indent=1)
        except OSError as exc:
            self._failed(REPORT_JSON, exc)
            return False
        if self._claim_held:  # the folder holds this flight's report now: the claim marker can go
            release_claim(self.out_dir)
            self._claim_held = False
        return True

    def _failed(self, what: str, exc: BaseException) -> None:
        line = f"{what}: {exc}"
        if line not in self.recording_errors:
            self.recording_errors.append(line)
            log.error("could not write %s in %s: %s; the flight goes on", what, self.out_dir, exc)

    def finish(self, summary: dict[str, Any], tlog: Path | None = None) -> dict[str, Any]:
        """Write the final report.json, the plot and the GIF; returns the JSON written (without steps).

        `final["report_written"]` says whether report.json holds this final state (with every step, or
        `steps_omitted` when only the summary fitted)."""
        files: dict[str, str | None] = {"report": REPORT_JSON, "trajectory": None, "gif": None, "tlog": None}
        for name, writer in (("trajectory", self._plot), ("gif", self._gif)):
            if not self.media:
                continue
            try:
                files[name] = writer()
            except OSError as exc:
                self._failed(name, exc)
            except Exception:  # a plot that fails must not lose the report itself
                log.exception("could not write the %s of %s", name, self.out_dir)
        if tlog is not None and tlog.exists():
            files["tlog"] = os.path.relpath(tlog, self.out_dir)
        with contextlib.suppress(OSError):
            self._reserve.unlink()  # its room is the final report's
        final = {"status": "finished", **summary, "timing": timing_summary(self.steps), "files": files}
        final["recording_errors"] = self.recording_errors
        written = self._write(final)
        if not written:  # the steps did not fit: the outcome without them, if that does
            final["steps_omitted"] = len(self.steps)
            final["recording_errors"] = list(self.recording_errors)
            written = self._write(final, with_steps=False)
        final["report_written"] = written
        return final

    def _gif(self) -> str | None:
        if not self.steps:
            return None
        eps = self.epsilon_px
        frames = [Image.fromarray(annotate(s.frame.image, s.detection, eps, s.action)) for s in self.steps]
        buffer = io.BytesIO()
        frames[0].save(
            buffer,
            format="GIF",
            save_all=True,
            append_images=frames[1:],
            duration=GIF_FRAME_MS,
            loop=0,
            optimize=False,
        )
        write_atomic(self.out_dir / CAMERA_GIF, buffer.getvalue())
        return CAMERA_GIF

    def _plot(self) -> str | None:
        if not self.steps:
            return None
        east = [s.telemetry.position_ned.east_m for s in self.steps]
        up = [-s.telemetry.position_ned.down_m for s in self.steps]
        fig = Figure(figsize=(9.0, 4.0))
        ax_path, ax_off = fig.subplots(1, 2)
        several = len(self.instructions) > 1
        for number, entry in enumerate(self.instructions):
            at = [i for i, owner in enumerate(self.step_instruction) if owner == number]
            if at:
                label = f"{number + 1}: {entry.get('instruction', '')}"[:40] if several else None
                ax_path.plot([east[i] for i in at], [up[i] for i in at], "-o", markersize=4, label=label)
        ax_path.plot(east[0], up[0], "s", color="tab:green", label="start")
        ax_path.plot(east[-1], up[-1], "*", color="tab:red", markersize=12, label="end")
        for i, s in enumerate(self.steps):
            if s.event in (StepEvent.LOST, StepEvent.RECOVERY):
                ax_path.annotate(s.event.value, (east[i], up[i]), fontsize=7)
        ax_path.set(xlabel="east (m) = right", ylabel="up (m)", title="drone path in the wall plane")
        ax_path.set_aspect("equal", adjustable="datalim")
        ax_path.legend(fontsize=8)
        index = list(range(len(self.steps)))
        for label, values, style in (
            ("detector", [s.offset_px for s in self.steps], "-o"),
            ("truth", [s.truth_offset_px for s in self.steps], "--x"),
        ):
            norms = [math.nan if v is None else max(abs(v[0]), abs(v[1])) for v in values]
            if not all(math.isnan(n) for n in norms):
                ax_off.plot(index, norms, style, label=label, markersize=4)
        ax_off.axhline(self.epsilon_px, color="gold", label="ε")
        ax_off.set(xlabel="step", ylabel="max(|du|, |dv|) (px)", title="offset from the image centre")
        ax_off.legend(fontsize=8)
        # Fixed margins that fit these labels: `tight_layout` drew the figure once more to measure them
        # (about a third of a mission report's CPU time).
        fig.subplots_adjust(left=0.08, right=0.98, bottom=0.13, top=0.91, wspace=0.25)
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=90)
        write_atomic(self.out_dir / TRAJECTORY_PNG, buffer.getvalue())
        return TRAJECTORY_PNG
