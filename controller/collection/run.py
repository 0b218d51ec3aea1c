"""`collect_flown(config)`: fly the collection protocol through the Vehicle interface and write the dataset.

connect → the goal (here / scene / FILE, `goal_flight`) → the plan (`plan`, written beside the dataset)
→ for each capture not yet taken: fly to its pose (bounded speed, `pose_flight`), settle, take a frame
that arrived after settling, label it (`labels`), write the PNG and its row → back to the goal → land.

Safety: the vehicle is behind `flight.safe_vehicle.SafeVehicle` (speed limits, the setpoint watchdog)
and, once the goal is recorded, a geofence around it (`--fence-m`, which the box must fit). A lost
camera holds, waits `--loss-wait-s` for frames, then lands (`--on-loss land`) or flies back to the goal
pose and holds there for the pilot (`--on-loss return`); a lost link can command nothing (the vehicle's
own failsafe acts); any error, Ctrl-C or SIGTERM holds and lands, as a mission does. Whatever happens,
every capture taken is on disk with its row, `dataset.json` says the collection is incomplete, and
`--resume` goes on with the captures not taken.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from controller.collection.config import GOAL_HERE, GOAL_SCENE, FlownCollectConfig
from controller.collection.contact_sheet import write_contact_sheet
from controller.collection.goal import GoalRecord, load_goal, save_goal
from controller.collection.goal_flight import (
    centre_by_image,
    climb_to,
    fresh_frame,
    record_goal,
    take_offboard_here,
    verify_goal,
)
from controller.collection.labels import LabelMaker
from controller.collection.plan import PlannedCapture, PlanSettings, plan_captures
from controller.collection.pose_flight import PoseControl, fly_to, pose_of
from controller.collection.vehicles import SIM_CAMERA_OFFSET_FRD_M, open_collection_vehicle
from controller.collection.writer import FlownDataset
from drone_inspect_core.centring import default_epsilon_px, sector_of_offset
from drone_inspect_core.dataset import FLOWN, is_flagged
from drone_inspect_core.targets import TARGET_KINDS
from flight.errors import FlightError, FlightTimeoutError
from flight.safe_vehicle import SafeVehicle
from flight.safety import GeofenceBox, SafetyLimits, safe_stop
from flight.signals import StopRequested
from flight.vehicle import Vehicle
from perception.camera import Camera
from perception.camera_model import CameraModel, load_camera_file
from perception.errors import CameraError

log = logging.getLogger(__name__)

FORMAT = "dronectl.flown/1"
SIM_IMAGE_PX, SIM_HFOV_DEG = 224, 60.0


class CameraLostError(RuntimeError):
    """The camera sent nothing for `loss_wait_s`: the collection stopped (the vehicle landed or returned)."""


class CollectionInputError(ValueError):
    """Bad input found before anything flies (a kind, a file, a folder); one line naming it."""


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


@dataclass(frozen=True)
class FlownResult:
    out_dir: Path
    complete: bool
    counts: dict[str, int]
    flagged: int
    tally: CollectionTally
    contact_sheet: Path | None


def camera_model_for(config: FlownCollectConfig) -> CameraModel:
    """The camera file's model, else the simulated camera's (a real vehicle needs a camera file)."""
    if config.camera_file is not None:
        return load_camera_file(config.camera_file)
    if config.simulated:
        return CameraModel.from_fov(
            SIM_IMAGE_PX, SIM_IMAGE_PX, SIM_HFOV_DEG, offset_frd_m=SIM_CAMERA_OFFSET_FRD_M
        )
    raise CollectionInputError(
        "--camera-file: a real vehicle's camera needs its intrinsics (a file with width, height and hfov_deg "
        "or a calibrated matrix; docs/own-target.md)"
    )


def check_inputs(config: FlownCollectConfig) -> tuple[CameraModel, GoalRecord | None]:
    """Everything that can be checked before connecting: the kind, the camera file, the goal file."""
    if config.kind not in TARGET_KINDS:
        raise CollectionInputError(
            f"--kind {config.kind!r}: unknown kind; known kinds: {', '.join(TARGET_KINDS)}"
        )
    model = camera_model_for(config)
    goal = None
    if config.goal not in (GOAL_HERE, GOAL_SCENE) and not config.resume:
        goal = load_goal(config.goal)
        if goal.kind != config.kind:
            raise CollectionInputError(f"--goal {config.goal}: a goal for a {goal.kind}, not a {config.kind}")
        if goal.image_size != (model.width, model.height):
            raise CollectionInputError(
                f"--goal {config.goal}: its image is {goal.image_size[0]}x{goal.image_size[1]} px, the "
                f"camera's {model.width}x{model.height}"
            )
    return model, goal


def safety_limits(config: FlownCollectConfig) -> SafetyLimits:
    """The speed limits (the geofence comes once the goal is known: `goal_fence`)."""
    return SafetyLimits(
        max_horizontal_speed_m_s=config.max_speed_m_s,
        max_vertical_speed_m_s=min(0.5, config.max_speed_m_s),
        max_yaw_rate_deg_s=30.0,
    )


def goal_fence(config: FlownCollectConfig, yaw_deg: float) -> GeofenceBox:
    """`--fence-m` (in the goal's heading frame) as the NED-aligned box that holds it."""
    c, s = abs(math.cos(math.radians(yaw_deg))), abs(math.sin(math.radians(yaw_deg)))
    f = config.fence
    return GeofenceBox(
        half_width_north_m=c * f.forward_m + s * f.right_m,
        half_width_east_m=s * f.forward_m + c * f.right_m,
        max_up_m=f.up_m,
        max_down_m=f.up_m,
        breach_margin_m=0.2,
    )


OnCapture = Callable[[dict[str, Any], Any, Any], None]
"""`on_capture(row, opened_vehicle, simulated_vehicle_or_None)`, after each capture is written."""


def collect_flown(config: FlownCollectConfig, on_capture: OnCapture | None = None) -> FlownResult:
    """Fly the collection into `config.out_dir` (or go on with `--resume`); see the module docstring.

    `on_capture` is called after each capture is written (tests inject faults there).
    """
    model, goal = check_inputs(config)
    dataset = FlownDataset(config.out_dir, config.resume)
    if config.resume:
        goal = load_goal(config.out_dir)
        if goal.kind != config.kind:
            raise CollectionInputError(f"--resume: the dataset is of a {goal.kind}, not --kind {config.kind}")
    epsilon = config.epsilon_px or default_epsilon_px(model.width)
    agree = config.agree_px or 0.1 * model.width
    tally = CollectionTally()
    started = _now()
    wall0 = time.perf_counter()
    complete = False
    plan: list[PlannedCapture] = []
    try:
        with open_collection_vehicle(config, dataset.flight_dir) as (opened, sim):
            safe = SafeVehicle(opened.vehicle, safety_limits(config))
            dataset.write_meta(
                _meta(config, model, epsilon, agree, dataset, goal, plan, tally, started, False)
            )
            safe.connect()
            vehicle0 = math.nan
            try:
                goal, seen_at_goal = _reach_goal(safe, opened.camera, model, config, goal, sim, agree)
                if not config.resume:
                    save_goal(goal, model, dataset.root)
                    plan = plan_captures(model, goal.geometry(), _plan_settings(config, epsilon, model.width))
                    dataset.save_plan(plan)
                else:
                    plan = dataset.load_plan()
                safe.limits = replace(safe.limits, geofence=goal_fence(config, goal.pose.yaw_deg))
                safe.origin = _position(goal)
                dataset.write_meta(
                    _meta(config, model, epsilon, agree, dataset, goal, plan, tally, started, False)
                )
                labels = LabelMaker(model, goal, agree)
                if seen_at_goal is not None:  # a goal flown to again: the pose estimate's drift since then
                    labels.observe(seen_at_goal, pose_of(safe.telemetry()))
                vehicle0 = safe.time_s()
                _fly_captures(safe, opened, sim, dataset, plan, labels, config, epsilon, tally, on_capture)
                tally.vehicle_s = safe.time_s() - vehicle0
                complete = all(c.id in dataset.taken or c.id in tally.skipped for c in plan)
                fly_to(safe, goal.pose, _control(config), config.settling)
                safe.stop_offboard()
                safe.land()
                safe.disarm()
                tally.ended_by = "complete" if complete else "captures skipped"
            except CameraLostError as exc:
                tally.ended_by = f"camera lost: {exc}"
                _on_camera_loss(safe, config, goal)
                raise
            except (Exception, KeyboardInterrupt) as exc:
                tally.ended_by = _why(exc)
                log.error(
                    "collection interrupted (%s): holding, then landing; the captures so far are kept",
                    tally.ended_by,
                )
                safe_stop(safe)
                raise
            finally:
                if math.isfinite(vehicle0) and not tally.vehicle_s:
                    with contextlib.suppress(FlightError):
                        tally.vehicle_s = safe.time_s() - vehicle0
    finally:
        tally.wall_s = time.perf_counter() - wall0
        dataset.close()
        dataset.write_meta(
            _meta(config, model, epsilon, agree, dataset, goal, plan, tally, started, complete)
        )
        sheet = write_contact_sheet(dataset.root, dataset.rows, epsilon, dataset.root / "contact_sheet.png")
    counts = dict(Counter(row["split"] for row in dataset.rows if not is_flagged(row)))
    flagged = sum(1 for row in dataset.rows if is_flagged(row))
    return FlownResult(dataset.root, complete, counts, flagged, tally, sheet)


def _why(exc: BaseException) -> str:
    if isinstance(exc, StopRequested):
        return str(exc)
    if isinstance(exc, KeyboardInterrupt):
        return "stopped by Ctrl-C"
    return f"{type(exc).__name__}: {exc}"


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def _position(goal: GoalRecord) -> Any:
    from flight.types import PositionNed

    return PositionNed(goal.pose.north_m, goal.pose.east_m, goal.pose.down_m)


def _control(config: FlownCollectConfig) -> PoseControl:
    return PoseControl(max_speed_m_s=config.max_speed_m_s, max_vertical_m_s=min(0.4, config.max_speed_m_s))


def _plan_settings(config: FlownCollectConfig, epsilon: float, width_px: int) -> PlanSettings:
    return PlanSettings(
        n_goal=config.n_goal,
        n_per_sector=config.n_per_sector,
        n_empty=config.n_empty,
        box=config.box,
        epsilon_px=epsilon,
        block_size=config.block_size,
        test_every=config.test_every,
        empty_yaw_deg=config.empty_yaw_deg,
        min_altitude_m=config.min_altitude_m,
        seed=config.seed,
    )


def _reach_goal(
    vehicle: Vehicle,
    camera: Camera,
    model: CameraModel,
    config: FlownCollectConfig,
    goal: GoalRecord | None,
    sim: Any,
    agree_px: float,
) -> tuple[GoalRecord, tuple[float, float] | None]:
    """Fly to (or record) the goal; see `controller.collection.goal_flight`. Also where the target is seen
    at a goal flown to again (FILE, --resume), None for a goal recorded now."""
    control = _control(config)
    if goal is not None:  # --goal FILE, or --resume
        climb_to(vehicle, goal.pose.down_m, {})
        fly_to(vehicle, goal.pose, control, config.settling)
        return goal, verify_goal(vehicle, camera, model, goal, agree_px)
    if config.goal == GOAL_SCENE:
        climb = sim.takeoff_climb_m()
        climb_to(vehicle, vehicle.telemetry().position_ned.down_m - climb, {})
        right_m, up_m = sim.centred_offset_m(climb)
        here = pose_of(vehicle.telemetry())
        fly_to(vehicle, here.moved(0.0, right_m, up_m), control, config.settling)
        if config.goal_box_px is None:
            centre_by_image(vehicle, camera, model, config, control)
    else:
        take_offboard_here(vehicle)
    return record_goal(vehicle, camera, model, config), None


def _fly_captures(
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
    control = _control(config)
    todo = [c for c in plan if c.id not in dataset.taken]
    bar = tqdm(total=len(todo), unit="img", desc="collect (flown)", disable=not config.progress)
    try:
        for attempt in (1, 2):
            retry = []
            for capture in todo:
                row = _capture(
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


def _capture(
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
    frame = _read_or_wait(vehicle, camera, config)
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
        "wall_time": _now(),
        "frame_number": frame.frame_number,
        "planned": {"kind": capture.kind, "sector": capture.sector, "offset_px": capture.wanted_offset_px},
        "settle_s": round(arrival.settle_s, 3),
        "label": label.record(labels.agree_px, labels.goal.depth_m, labels.goal.distance_source),
    }
    if truth is not None:
        row["truth"] = {**truth["target"], "frame_number": truth["frame_number"], "drone": truth["drone"]}
    return dataset.write_capture(capture.id, frame.image, row)


def _read_or_wait(vehicle: Vehicle, camera: Camera, config: FlownCollectConfig) -> Any:
    """A frame that arrived once settled; a camera that sends nothing is waited for `loss_wait_s`
    (holding), then `CameraLostError`."""
    settled_at = time.monotonic()
    try:
        return fresh_frame(camera, settled_at)
    except CameraError as exc:
        log.warning("camera: %s; holding and waiting %.0f s for it", exc, config.loss_wait_s)
        vehicle.hold()
        give_up = time.monotonic() + config.loss_wait_s
        while time.monotonic() < give_up:
            try:
                return fresh_frame(camera, time.monotonic(), timeout_s=1.0)
            except CameraError:
                vehicle.sleep(0.1)
        raise CameraLostError(str(exc)) from None


def _on_camera_loss(vehicle: Vehicle, config: FlownCollectConfig, goal: GoalRecord | None) -> None:
    """`--on-loss land`: land where it is; `return`: fly back to the goal pose and hold there (Hold mode)."""
    if config.on_loss == "return" and goal is not None:
        try:
            log.error("camera lost: flying back to the goal pose and holding there (--on-loss return)")
            fly_to(vehicle, goal.pose, _control(config), config.settling)
            vehicle.stop_offboard()
            return
        except FlightError as exc:
            log.error("could not return to the goal pose (%s): landing", exc)
    log.error("camera lost: holding, then landing (--on-loss land)")
    safe_stop(vehicle)


def _meta(
    config: FlownCollectConfig,
    model: CameraModel,
    epsilon: float,
    agree: float,
    dataset: FlownDataset,
    goal: GoalRecord | None,
    plan: list[PlannedCapture],
    tally: CollectionTally,
    started: str,
    complete: bool,
) -> dict[str, Any]:
    """`dataset.json` of a flown collection (written at the start, once the goal is known, and at the end)."""
    previous = dataset.meta
    flights = [f for f in previous.get("flights", []) if f.get("flight") != dataset.flight]
    flights.append(
        {
            "flight": dataset.flight,
            "vehicle": config.vehicle,
            "started": started,
            "ended": _now(),
            "captures": tally.taken,
            "flagged": tally.flagged,
            "skipped": tally.skipped,
            "wall_s": round(tally.wall_s, 2),
            "vehicle_s": round(tally.vehicle_s, 2),
            **tally.rates(),
            "ended_by": tally.ended_by,
        }
    )
    planned = previous.get("planned_counts") or dict(Counter(c.split for c in plan))
    return {
        "source": FLOWN,
        "format": FORMAT,
        "created_by": "dronectl collect --vehicle",
        "complete": complete,
        "camera": {
            **model.as_dict(),
            "source": str(config.camera_file) if config.camera_file else "simulated",
        },
        "epsilon_px": epsilon,
        "agree_px": agree,
        "kind": config.kind,
        "sectors": "where the target lies in the image: N = above centre (dv < -eps, |du| <= eps), "
        "E = right (du > eps), ...; 'centre' = within eps on both axes; 'none' = out of view",
        "goal": None if goal is None else goal.as_dict(model),
        "protocol": {
            "box_m": config.box.as_list(),
            "fence_m": config.fence.as_list(),
            "n_goal": config.n_goal,
            "n_per_sector": config.n_per_sector,
            "n_empty": config.n_empty,
            "block_size": config.block_size,
            "test_every": config.test_every,
            "empty_yaw_deg": config.empty_yaw_deg,
            "max_speed_m_s": config.max_speed_m_s,
            "settling": asdict(config.settling),
            "seed": config.seed,
            "on_loss": config.on_loss,
            "split": "time blocks: every test_every-th block of sector captures is 'test'",
        },
        "vehicle": config.vehicle,
        "camera_url": config.camera,
        "simulator": None
        if not config.simulated
        else {
            "scene_file": None if config.sim.scene_file is None else str(config.sim.scene_file),
            "scene_seed": config.sim.scene_seed,
            "sim_speed": config.sim.sim_speed,
            "px4_speed": config.sim.px4_speed,
        },
        "counts": dict(Counter(row["split"] for row in dataset.rows)),
        "planned_counts": planned,
        "flagged": sum(1 for row in dataset.rows if is_flagged(row)),
        "flights": flights,
    }
