"""The captures of a flown collection: fly to each planned pose, take it once settled, label it, write it.

`fly_captures` goes through the plan's captures not taken yet (one that does not settle is tried once more
at the end, then named as skipped); `capture_one` is one of them, from the flight to the written row
(`docs/own-target.md` lists its fields). A camera that sends nothing is waited for while the vehicle holds
(`read_or_wait`), then `CameraLostError`; `on_camera_loss` then lands or flies back to the goal and holds.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from tqdm import tqdm

from controller.collection.config import FlownCollectConfig
from controller.collection.goal import GoalRecord
from controller.collection.goal_flight import FRAME_WAIT_S
from controller.collection.labels import LabelMaker
from controller.collection.plan import PlannedCapture
from controller.collection.pose_flight import PoseControl, fly_to, pose_of
from controller.collection.writer import FlownDataset
from drone_inspect_core.centring import sector_of_offset
from drone_inspect_core.dataset import is_flagged
from flight.errors import FlightError, FlightTimeoutError
from flight.safety import safe_stop
from flight.vehicle import Vehicle
from perception.camera import Camera
from perception.errors import CameraError
from perception.fresh_frame import read_fresh

log = logging.getLogger(__name__)


class CameraLostError(RuntimeError):
    """The camera sent nothing for `loss_wait_s`: the collection stopped (the vehicle landed or returned)."""


@dataclass
class CollectionTally:
    """What this flight did, for the summary and `dataset.json`'s `flights`."""

    taken: int = 0
    flagged: int = 0
    skipped: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    vehicle_s: float = 0.0
    ended_by: str = "running"

    def rates(self) -> dict[str, float | None]:
        per = self.taken * 60.0
        return {
            "images_per_wall_min": round(per / self.wall_s, 2) if self.wall_s > 0 else None,
            "images_per_vehicle_min": round(per / self.vehicle_s, 2) if self.vehicle_s > 0 else None,
        }


OnCapture = Callable[[dict[str, Any], Any, Any], None]
"""`on_capture(row, opened_vehicle, simulated_vehicle_or_None)`, after each capture is written."""


def now_iso() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def control_for(config: FlownCollectConfig) -> PoseControl:
    return PoseControl(max_speed_m_s=config.max_speed_m_s, max_vertical_m_s=min(0.4, config.max_speed_m_s))


def fly_captures(
    vehicle: Vehicle,
    opened: Any,
    sim: Any,
    dataset: FlownDataset,
    plan: list[PlannedCapture],
    labels: LabelMaker,
    config: FlownCollectConfig,
    epsilon: float,
    tally: CollectionTally,
    on_capture: OnCapture | None,
) -> None:
    """Every planned capture not taken yet; one that does not settle is tried again at the end, once."""
    control = control_for(config)
    todo = [c for c in plan if c.id not in dataset.taken]
    bar = tqdm(total=len(todo), unit="img", desc="collect (flown)", disable=not config.progress)
    try:
        for attempt in (1, 2):
            retry = []
            for capture in todo:
                row = capture_one(
                    vehicle, opened.camera, sim, capture, labels, config, control, epsilon, dataset
                )
                if row is None:
                    retry.append(capture)
                    continue
                tally.taken += 1
                tally.flagged += int(is_flagged(row))
                bar.update(1)
                bar.set_postfix(flagged=tally.flagged)
                if on_capture is not None:
                    on_capture(row, opened, sim)
            todo = retry
            if todo and attempt == 1:
                log.warning("%d captures did not settle: trying them once more", len(todo))
        tally.skipped = [c.id for c in todo]
    finally:
        bar.close()


def capture_one(
    vehicle: Vehicle,
    camera: Camera,
    sim: Any,
    capture: PlannedCapture,
    labels: LabelMaker,
    config: FlownCollectConfig,
    control: PoseControl,
    epsilon: float,
    dataset: FlownDataset,
) -> dict[str, Any] | None:
    """Fly to one capture's pose and take it (None: it did not settle or could not be reached)."""
    try:
        arrival = fly_to(vehicle, capture.pose, control, config.settling)
    except FlightTimeoutError as exc:
        log.warning("%s: %s", capture.id, exc)
        return None
    if not arrival.settled:
        log.warning("%s: not settled within %.0f s", capture.id, config.settling.timeout_s)
        return None
    frame = read_or_wait(vehicle, camera, config)
    telemetry = vehicle.telemetry()
    truth = sim.truth.frame() if sim is not None else None
    pose = pose_of(telemetry)
    label = labels.label(frame.image, pose)
    forward, right, up = pose.relative_to(labels.goal.pose)
    sector = sector_of_offset(*label.offset_px, epsilon) if label.in_view else "none"
    split = capture.split
    if split == "goal" and sector != "centre":
        split = "train"  # a goal capture that flew out of ε is a sector image like any other
    u, v = label.offset_px[0] + labels.camera.width / 2, label.offset_px[1] + labels.camera.height / 2
    row: dict[str, Any] = {
        "split": split,
        "sector": sector,
        "target_kind": config.kind,
        "centre_px": [round(u, 3), round(v, 3)],
        "offset_px": [round(label.offset_px[0], 3), round(label.offset_px[1], 3)],
        "bbox_px": None if label.bbox_px is None else [round(x, 3) for x in label.bbox_px],
        "in_view": label.in_view,
        "fully_in_view": label.fully_in_view,
        "drone": {
            "position_ned_m": [round(x, 4) for x in pose.position.tolist()],
            "yaw_deg": round(pose.yaw_deg, 3),
            "velocity_ned_m_s": [
                round(x, 4)
                for x in (
                    telemetry.velocity_ned.north_m_s,
                    telemetry.velocity_ned.east_m_s,
                    telemetry.velocity_ned.down_m_s,
                )
            ],
            "roll_deg": round(telemetry.attitude.roll_deg, 3),
            "pitch_deg": round(telemetry.attitude.pitch_deg, 3),
            "forward_range_m": telemetry.forward_range_m,
        },
        "offset_m": {
            "right_m": round(right, 4),
            "up_m": round(up, 4),
            "forward_m": round(forward, 4),
            "yaw_deg": round(pose.yaw_deg - labels.goal.pose.yaw_deg, 3),
        },
        "flight": dataset.flight,
        "block": capture.block,
        "time_s": round(telemetry.timestamp_s, 4),
        "wall_time": now_iso(),
        "frame_number": frame.frame_number,
        "planned": {"kind": capture.kind, "sector": capture.sector, "offset_px": capture.wanted_offset_px},
        "settle_s": round(arrival.settle_s, 3),
        "label": label.record(labels.agree_px, labels.goal.depth_m, labels.goal.distance_source),
    }
    if truth is not None:
        row["truth"] = {**truth["target"], "frame_number": truth["frame_number"], "drone": truth["drone"]}
    return dataset.write_capture(capture.id, frame.image, row)


def read_or_wait(vehicle: Vehicle, camera: Camera, config: FlownCollectConfig) -> Any:
    """A frame that arrived once settled (`FlownCollectConfig.frame_lag_s` after);
    a camera that sends nothing is waited for `loss_wait_s` (holding), then `CameraLostError`."""
    try:
        return read_fresh(camera, time.monotonic(), config.frame_lag_s, FRAME_WAIT_S)
    except CameraError as exc:
        log.warning("camera: %s; holding and waiting %.0f s for it", exc, config.loss_wait_s)
        vehicle.hold()
        give_up = time.monotonic() + config.loss_wait_s
        while time.monotonic() < give_up:
            try:
                return read_fresh(camera, time.monotonic(), 0.0, 1.0)
            except CameraError:
                vehicle.sleep(0.1)
        raise CameraLostError(str(exc)) from None


def on_camera_loss(vehicle: Vehicle, config: FlownCollectConfig, goal: GoalRecord | None) -> None:
    """`--on-loss land`: land where it is; `return`: fly back to the goal pose and hold there (Hold mode)."""
    if config.on_loss == "return" and goal is not None:
        try:
            log.error("camera lost: flying back to the goal pose and holding there (--on-loss return)")
            fly_to(vehicle, goal.pose, control_for(config), config.settling)
            vehicle.stop_offboard()
            return
        except FlightError as exc:
            log.error("could not return to the goal pose (%s): landing", exc)
    log.error("camera lost: holding, then landing (--on-loss land)")
    safe_stop(vehicle)
