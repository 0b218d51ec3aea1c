"""A mission as a Rerun recording (`dronectl fly --rerun FILE.rrd`): open it with `rerun FILE.rrd`.

Optional (`pip install -e '.[rerun]'`). Per loop step, on three timelines, `sim_time` (the
vehicle's clock: simulated seconds in a simulator), `step` (counted over the whole flight) and
`instruction` (1, 2, ...: which of the flight's instructions the step belongs to):

- `instruction`: each instruction's text as it begins (a text log), so a flight of several
  instructions shows which one every step served;

- `camera/image`: the frame the loop decided on (JPEG); `camera/image/detection`: the
  detector's box, labelled with kind and confidence; `camera/image/epsilon`: the ε box around
  the image centre (green once centred); `camera/image/centre`: the image centre.
- `planner/distance/<action>`: the planner's nine distances (lower is better) and
  `planner/action`: the chosen action and the step's event, as a text log.
- `move/commanded/{right_m,up_m}` and `move/flown/{right_m,up_m,forward_m}`: each move.
- `offset/detector/{du,dv}` and, in a simulator, `offset/truth/{du,dv}`, in pixels.
- `world/trajectory`: the drone's path so far in 3D (east, north, up from the local origin)
  and `world/drone`: where it is now.

A recording that fails (disk full, a bad value) logs the error and stops recording; it never
aborts the flight or costs the report. The recording is kept in memory and written whole when the
flight ends (`drone_inspect_core.files.write_new`): Rerun's own file sink writes from a thread of its
own and a full disk there cut the file silently, left looking whole. A file that cannot be written is
said in the report; none is left half-written.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from controller.planning.actions import ALL_ACTIONS
from controller.planning.loop_records import StepRecord
from drone_inspect_core.files import write_new

log = logging.getLogger(__name__)

APPLICATION_ID = "drone-inspect"


class RerunUnavailableError(RuntimeError):
    """The rerun-sdk package is not installed."""


class RerunFileError(RuntimeError):
    """The recording's path cannot be used (it exists, or its folder does not)."""


def check_rerun_path(path: str | Path) -> Path:
    """`path` as a new .rrd file: refused if it exists (a recording is never overwritten) or its
    folder does not; raises `RerunUnavailableError` when rerun-sdk is missing. Call before takeoff."""
    path = Path(path)
    if path.suffix != ".rrd":
        raise RerunFileError(f"--rerun {path}: the file name must end in .rrd")
    if path.exists():
        raise RerunFileError(f"--rerun {path}: the file exists; a recording is never overwritten")
    if not path.parent.is_dir():
        raise RerunFileError(f"--rerun {path}: folder {path.parent} does not exist")
    try:
        import rerun  # noqa: F401
    except ImportError as exc:
        raise RerunUnavailableError(
            "--rerun needs the Rerun SDK: pip install -e '.[rerun]' (or pip install rerun-sdk)"
        ) from exc
    return path


class RerunRecorder:
    """Writes one mission's steps to a new .rrd file as they happen (see the module doc)."""

    def __init__(self, path: str | Path, epsilon_px: float, header: dict[str, Any]) -> None:
        self.path = check_rerun_path(path)
        import rerun as rr

        self._rr = rr
        self.epsilon_px = epsilon_px
        self._track: list[list[float]] = []
        self._failed = False
        self._steps = 0  # over the whole flight: each instruction's loop counts its own from 0
        self._instruction = 0
        self.rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"{header.get('mission', 'mission')}")
        self._stream = self.rec.binary_stream()
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lines = [f"**{key}**: {header.get(key)}" for key in ("mission", "planner", "vehicle")]
        lines += [
            f"**instruction {i}**: {text}" for i, text in enumerate(header.get("instructions_planned", []), 1)
        ]
        lines.append(f"**ε**: {epsilon_px:g} px")
        self.rec.log("mission", rr.TextDocument("\n\n".join(lines), media_type="text/markdown"), static=True)

    def begin_instruction(self, index: int, text: str) -> None:
        """Instruction `index` (1, 2, ...) of the flight begins: its text on the `instruction` timeline."""
        if self._failed:
            return
        self._instruction = index
        self.rec.set_time("instruction", sequence=index)
        self.rec.set_time("step", sequence=self._steps)
        self.rec.log("instruction", self._rr.TextLog(f"{index}: {text}", level="INFO"))

    def add_step(self, step: StepRecord) -> None:
        if self._failed:
            return
        try:
            self._log_step(step)
        except Exception:  # the recording is an extra: it never ends a flight
            self._failed = True
            log.exception("rerun recording %s failed; recording stopped, the flight goes on", self.path)

    def _log_step(self, step: StepRecord) -> None:
        rr, rec = self._rr, self.rec
        rec.set_time("step", sequence=self._steps)
        rec.set_time("instruction", sequence=self._instruction)
        self._steps += 1
        rec.set_time("sim_time", duration=float(step.vehicle_time_s))
        image = step.frame.image
        h, w = image.shape[:2]
        rec.log("camera/image", rr.Image(image).compress(jpeg_quality=90))
        eps = self.epsilon_px
        colour = (0, 220, 0) if step.centred else (255, 220, 0)
        rec.log(
            "camera/image/epsilon",
            rr.Boxes2D(centers=[[w / 2, h / 2]], half_sizes=[[eps, eps]], colors=[colour]),
        )
        rec.log("camera/image/centre", rr.Points2D([[w / 2, h / 2]], radii=1.5, colors=[colour]))
        if step.detection is not None:
            x0, y0, x1, y1 = step.detection.bbox_px
            label = f"{step.detection.kind or 'target'} {step.detection.confidence:.2f}"
            rec.log(
                "camera/image/detection",
                rr.Boxes2D(array=[[x0, y0, x1, y1]], array_format=rr.Box2DFormat.XYXY, labels=[label]),
            )
        else:
            rec.log("camera/image/detection", rr.Clear(recursive=False))
        for name, offset in (("detector", step.offset_px), ("truth", step.truth_offset_px)):
            if offset is not None:
                rec.log(f"offset/{name}/du", rr.Scalars(float(offset[0])))
                rec.log(f"offset/{name}/dv", rr.Scalars(float(offset[1])))
        if step.distances is not None:
            for action, distance in zip(ALL_ACTIONS, step.distances, strict=True):
                rec.log(f"planner/distance/{action.name.replace('/', '_')}", rr.Scalars(float(distance)))
        if step.action is not None or step.event.value:
            action = step.action.name if step.action else "-"
            text = f"instruction {self._instruction} step {step.index}: {action} {step.event.value}".strip()
            rec.log("planner/action", rr.TextLog(text))
        if step.move_m is not None:
            rec.log("move/commanded/right_m", rr.Scalars(float(step.move_m[0])))
            rec.log("move/commanded/up_m", rr.Scalars(float(step.move_m[1])))
        self._add_pose(step.telemetry.position_ned)
        if step.move is not None:
            d = step.move.displacement
            rec.log("move/flown/right_m", rr.Scalars(float(d.right_m)))
            rec.log("move/flown/up_m", rr.Scalars(float(-d.down_m)))
            rec.log("move/flown/forward_m", rr.Scalars(float(d.forward_m)))
            rec.set_time(
                "sim_time",
                duration=float(step.vehicle_time_s + step.move.duration_s + step.move.settle_time_s),
            )
            self._add_pose(step.move.end_position_ned)

    def _add_pose(self, position_ned: Any) -> None:
        rr = self._rr
        point = [float(position_ned.east_m), float(position_ned.north_m), float(-position_ned.down_m)]
        self._track.append(point)
        self.rec.log("world/trajectory", rr.LineStrips3D([self._track], colors=[(80, 160, 255)]))
        self.rec.log("world/drone", rr.Points3D([point], radii=0.05, colors=[(255, 80, 80)]))

    def finish(self, outcome: str, message: str) -> None:
        """The outcome as a last text log, then the whole recording written to its file (also after a
        failure, what was recorded until then); raises OSError when the file cannot be written."""
        try:
            if not self._failed:
                self.rec.log("planner/action", self._rr.TextLog(f"{outcome}: {message}", level="INFO"))
        except Exception:
            log.exception("rerun recording %s: could not record the end", self.path)
        finally:
            self.rec.disconnect()
        data = self._stream.read()
        if not data:
            raise OSError(f"{self.path}: the recording holds nothing")
        write_new(self.path, data)
