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
import logging
import math
import time
from collections import Counter
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from controller.collection.capture import (
    CameraLostError,
    CollectionTally,
    OnCapture,
    control_for,
    fly_captures,
    now_iso,
    on_camera_loss,
)
from controller.collection.config import GOAL_SCENE, FlownCollectConfig
from controller.collection.contact_sheet import write_contact_sheet
from controller.collection.goal import GoalRecord, load_goal, save_goal
from controller.collection.goal_flight import (
    centre_by_image,
    centre_goal,
    climb_to,
    record_goal,
    shipped_detector,
    take_offboard_here,
    verify_goal,
)
from controller.collection.inputs import CheckedInputs, CollectionInputError, check_inputs
from controller.collection.labels import LabelMaker
from controller.collection.plan import PlannedCapture, PlanSettings, plan_captures
from controller.collection.pose_flight import fly_to, pose_of
from controller.collection.vehicles import open_collection_vehicle
from controller.collection.writer import FlownDataset
from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.dataset import FLOWN, is_flagged
from flight.errors import FlightError
from flight.safe_vehicle import SafeVehicle
from flight.safety import GeofenceBox, SafetyLimits, safe_stop
from flight.signals import StopRequested
from flight.vehicle import Vehicle
from perception.camera import Camera
from perception.camera_model import CameraModel

log = logging.getLogger(__name__)

FORMAT = "dronectl.flown/1"


@dataclass(frozen=True)
class FlownResult:
    out_dir: Path
    complete: bool
    counts: dict[str, int]
    flagged: int
    tally: CollectionTally
    contact_sheet: Path | None


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


def collect_flown(config: FlownCollectConfig, on_capture: OnCapture | None = None) -> FlownResult:
    """Fly the collection into `config.out_dir` (or go on with `--resume`); see the module docstring.

    `on_capture` is called after each capture is written (tests inject faults there).
    """
    checked = check_inputs(config)
    model, goal = checked.camera, checked.goal
    if goal is None and not config.resume and config.goal_box_px is None:
        shipped_detector()  # on the ground, before anything flies (see its docstring)
    dataset = FlownDataset(config.out_dir, config.resume)
    if config.resume:
        goal = load_goal(config.out_dir)
        if goal.kind != config.kind:
            raise CollectionInputError(f"--resume: the dataset is of a {goal.kind}, not --kind {config.kind}")
    epsilon = config.epsilon_px or default_epsilon_px(model.width)
    agree = config.agree_px or 0.1 * model.width
    tally = CollectionTally()
    started = now_iso()
    wall0 = time.perf_counter()
    complete = False
    plan: list[PlannedCapture] = []
    try:
        with open_collection_vehicle(config, dataset.flight_dir) as (opened, sim):
            safe = SafeVehicle(opened.vehicle, safety_limits(config))
            dataset.write_meta(
                _meta(config, checked, epsilon, agree, dataset, goal, plan, tally, started, False)
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
                    _meta(config, checked, epsilon, agree, dataset, goal, plan, tally, started, False)
                )
                labels = LabelMaker(model, goal, agree)
                if seen_at_goal is not None:  # a goal flown to again: the pose estimate's drift since then
                    labels.observe(seen_at_goal, pose_of(safe.telemetry()))
                vehicle0 = safe.time_s()
                fly_captures(safe, opened, sim, dataset, plan, labels, config, epsilon, tally, on_capture)
                tally.vehicle_s = safe.time_s() - vehicle0
                complete = all(c.id in dataset.taken or c.id in tally.skipped for c in plan)
                fly_to(safe, goal.pose, control_for(config), config.settling)
                safe.stop_offboard()
                safe.land()
                safe.disarm()
                tally.ended_by = "complete" if complete else "captures skipped"
            except CameraLostError as exc:
                tally.ended_by = f"camera lost: {exc}"
                on_camera_loss(safe, config, goal)
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
            _meta(config, checked, epsilon, agree, dataset, goal, plan, tally, started, complete)
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


def _position(goal: GoalRecord) -> Any:
    from flight.types import PositionNed

    return PositionNed(goal.pose.north_m, goal.pose.east_m, goal.pose.down_m)


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
    control = control_for(config)
    if goal is not None:  # --goal FILE, or --resume
        climb_to(vehicle, goal.pose.down_m, {})
        fly_to(vehicle, goal.pose, control, config.settling)
        seen = verify_goal(vehicle, camera, model, goal, agree_px, config.frame_lag_s)
        if config.resume:  # the plan was made around this goal: it stays
            return goal, seen
        return centre_goal(vehicle, camera, model, goal, config, control), None
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


def _meta(
    config: FlownCollectConfig,
    checked: CheckedInputs,
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
    model = checked.camera
    previous = dataset.meta
    flights = [f for f in previous.get("flights", []) if f.get("flight") != dataset.flight]
    flights.append(
        {
            "flight": dataset.flight,
            "vehicle": config.vehicle,
            "started": started,
            "ended": now_iso(),
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
        "kinds": checked.kinds,
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
