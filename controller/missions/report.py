"""The report folder of one mission: `report.json`, a trajectory plot, an annotated GIF (and a .tlog).

`ReportWriter` is fed each step as the loop records it and rewrites `report.json`
after every step (status `in_progress`), so a crash or Ctrl-C loses nothing that was
recorded; `finish()` (called from a `finally`) writes the final JSON, the plot and
the GIF. Nothing in the folder is needed to fly: it is for people and CI.

```
OUT/report.json       mission, outcome, judgement, steps, final offsets (truth, detector), timing
OUT/trajectory.png    the drone's path in the wall plane, and |offset| per step
OUT/camera.gif        each step's frame with bbox, ε box and the chosen action drawn on it
OUT/flight.tlog       MAVLink telemetry log (MAVLink flights only; see runner)
```
"""

from __future__ import annotations

import json
import logging
import math
import os
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure  # the object API: no pyplot state, no GUI backend
from PIL import Image

from controller.planning.loop_records import StepRecord
from perception.annotate import annotate
from perception.types import Detection

log = logging.getLogger(__name__)

REPORT_JSON = "report.json"
TRAJECTORY_PNG = "trajectory.png"
CAMERA_GIF = "camera.gif"
GIF_FRAME_MS = 600


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
        "event": step.event,
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


class ReportFolderError(FileExistsError):
    """The report folder already holds something: reports are never written over."""


def claim_report_dir(out_dir: str | Path) -> Path:
    """`out_dir`, created; `ReportFolderError` if it already exists with anything in it.

    A report folder holds one flight: writing a second flight there would truncate the
    first one's .tlog, replace its report and leave its plot and GIF beside the new one.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        held = ", ".join(sorted(p.name for p in out_dir.iterdir())[:4]) if out_dir.is_dir() else "a file"
        raise ReportFolderError(
            f"{out_dir} already exists and holds {held}: reports are never overwritten; "
            "give a new or empty folder"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir


def fresh_report_dir(base: str | Path) -> Path:
    """`base`, or `base-2`, `base-3`, ... : the first that does not exist yet (for default folder names)."""
    base = Path(base)
    candidate, n = base, 1
    while candidate.exists():
        n += 1
        candidate = base.with_name(f"{base.name}-{n}")
    return candidate


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
        "outcome": "error",
        "passed": False,
        "error": how,
        "steps": [],
        "files": {"report": REPORT_JSON, "trajectory": None, "gif": None, "tlog": None},
    }
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        _write_json_atomic(Path(out_dir) / REPORT_JSON, data)
    except OSError as exc:
        log.error("could not write the report of %s: %s", out_dir, exc)


def _write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")
    os.replace(tmp, path)


@dataclass
class ReportWriter:
    """Writes one mission's report folder; `add_step` after each step, `finish` once at the end."""

    out_dir: Path
    header: dict[str, Any]  # mission name, planner, ε, scene, ... (JSON-able)
    epsilon_px: float
    media: bool = True
    """Write the plot and the GIF (benchmarks turn this off: the JSON is what they need)."""
    steps: list[StepRecord] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.out_dir = Path(self.out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._write({"status": "in_progress"})

    @property
    def json_path(self) -> Path:
        return self.out_dir / REPORT_JSON

    def add_step(self, step: StepRecord) -> None:
        self.steps.append(step)
        self._write({"status": "in_progress"})

    def _write(self, summary: dict[str, Any]) -> None:
        data = {**self.header, **summary, "steps": [step_to_json(s) for s in self.steps]}
        _write_json_atomic(self.json_path, data)

    def finish(self, summary: dict[str, Any], tlog: Path | None = None) -> dict[str, Any]:
        """Write the final report.json, the plot and the GIF; returns the JSON written (without steps)."""
        files: dict[str, str | None] = {"report": REPORT_JSON, "trajectory": None, "gif": None, "tlog": None}
        for name, writer in (("trajectory", self._plot), ("gif", self._gif)):
            if not self.media:
                continue
            try:
                files[name] = writer()
            except Exception:  # a plot that fails must not lose the report itself
                log.exception("could not write the %s of %s", name, self.out_dir)
        if tlog is not None and tlog.exists():
            files["tlog"] = os.path.relpath(tlog, self.out_dir)
        final = {"status": "finished", **summary, "timing": timing_summary(self.steps), "files": files}
        self._write(final)
        return final

    def _gif(self) -> str | None:
        if not self.steps:
            return None
        eps = self.epsilon_px
        frames = [Image.fromarray(annotate(s.frame.image, s.detection, eps, s.action)) for s in self.steps]
        frames[0].save(
            self.out_dir / CAMERA_GIF,
            save_all=True,
            append_images=frames[1:],
            duration=GIF_FRAME_MS,
            loop=0,
            optimize=False,
        )
        return CAMERA_GIF

    def _plot(self) -> str | None:
        if not self.steps:
            return None
        east = [s.telemetry.position_ned.east_m for s in self.steps]
        up = [-s.telemetry.position_ned.down_m for s in self.steps]
        fig = Figure(figsize=(9.0, 4.0))
        ax_path, ax_off = fig.subplots(1, 2)
        ax_path.plot(east, up, "-o", color="tab:blue", markersize=4)
        ax_path.plot(east[0], up[0], "s", color="tab:green", label="start")
        ax_path.plot(east[-1], up[-1], "*", color="tab:red", markersize=12, label="end")
        for s in self.steps:
            if s.event in ("lost", "recovery"):
                ax_path.annotate(s.event, (east[s.index], up[s.index]), fontsize=7)
        ax_path.set(xlabel="east (m) = right", ylabel="up (m)", title="drone path in the wall plane")
        ax_path.set_aspect("equal", adjustable="datalim")
        ax_path.legend(fontsize=8)
        index = [s.index for s in self.steps]
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
        fig.tight_layout()
        fig.savefig(self.out_dir / TRAJECTORY_PNG, dpi=90)
        return TRAJECTORY_PNG
