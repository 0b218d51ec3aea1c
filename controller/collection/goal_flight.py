"""Getting to the goal pose and recording it: `--goal here`, `--goal scene` (simulated), `--goal FILE`.

- here: the operator has brought the vehicle to the centred pose (by hand, or with `dronectl move`); it
  must be in the air. Offboard is taken from a hover with a zero setpoint.
- scene (a simulated vehicle): take off, fly to the scene's centred pose as an operator would, and centre
  the target by the image (the detector's box, a few small moves through the pose geometry), then the
  same as `here`.
- FILE (and `--resume`): the goal of an earlier collection. Take off if on the ground, fly to its pose,
  and check with the image that the target is where the goal image had it: a vehicle whose local frame
  moved (another takeoff spot, a reset estimator) is refused, not flown around a wrong goal.

Recording: settle, average the pose over a moment, take the goal image, the target's box in it (the
operator's `--goal-box`, else the detector's for a kind it knows) and its distance (`--distance-m`, else the
forward rangefinder's median over a moment).
"""

from __future__ import annotations

import functools
import logging
import math
import statistics
import time
from typing import Any

import numpy as np

from controller.collection.config import FlownCollectConfig
from controller.collection.goal import CANDIDATE, GoalRecord, box_from_xywh, save_goal
from controller.collection.pose_flight import PoseControl, fly_to, pose_of, wait_settled
from flight.moves import take_off_to_start
from flight.types import VelocityBody
from flight.vehicle import Vehicle
from perception.camera import Camera
from perception.camera_model import CameraModel, PoseNed
from perception.fresh_frame import read_fresh
from perception.target_tracker import TemplateTracker
from perception.types import Frame

log = logging.getLogger(__name__)

SAMPLE_S = 0.6
"""How long the goal pose and the rangefinder are averaged over."""
FRAME_WAIT_S = 3.0
"""How long a picture taken once settled is waited for (`perception.fresh_frame.read_fresh`)."""
CENTRING_MOVES = 3
DETECTOR_FRAMES = 3
"""Frames the detector is tried on before the goal box must be given (`--goal-box`)."""


class GoalError(RuntimeError):
    """The goal cannot be recorded or reached (the message says what to do)."""


def take_offboard_here(vehicle: Vehicle) -> None:
    """`--goal here`: the vehicle is hovering where the operator left it; take offboard without moving."""
    vehicle.wait_ready()
    if not vehicle.telemetry().in_air:
        raise GoalError(
            "--goal here: the vehicle is on the ground; fly it to the pose that centres the target first "
            "(by hand, or with `dronectl move`), then run collect again"
        )
    vehicle.set_velocity_body(VelocityBody())
    vehicle.start_offboard()


def climb_to(vehicle: Vehicle, down_m: float, clock: dict[str, float]) -> None:
    """From the ground (or the air) into an offboard hover near the height of `down_m` (local NED)."""
    telemetry = vehicle.telemetry()
    if telemetry.in_air:
        vehicle.set_velocity_body(VelocityBody())
        vehicle.start_offboard()
        return
    altitude_m = max(0.5, telemetry.position_ned.down_m - down_m)
    take_off_to_start(vehicle, altitude_m, None, clock)


def sample_goal_pose(vehicle: Vehicle) -> tuple[PoseNed, float | None]:
    """The pose averaged over `SAMPLE_S` (yaw by its circular mean) and the rangefinder's median."""
    poses, ranges = [], []
    end_s = vehicle.time_s() + SAMPLE_S
    while vehicle.time_s() < end_s:
        telemetry = vehicle.telemetry()
        poses.append(pose_of(telemetry))
        if telemetry.forward_range_m is not None:
            ranges.append(telemetry.forward_range_m)
        vehicle.sleep(0.05)
    position = np.mean([p.position for p in poses], axis=0)
    yaw = math.degrees(
        math.atan2(
            sum(math.sin(math.radians(p.yaw_deg)) for p in poses),
            sum(math.cos(math.radians(p.yaw_deg)) for p in poses),
        )
    )
    pose = PoseNed(float(position[0]), float(position[1]), float(position[2]), yaw)
    return pose, statistics.median(ranges) if len(ranges) >= max(1, len(poses) // 3) else None


def goal_box(config: FlownCollectConfig, image: np.ndarray) -> tuple[tuple[float, float, float, float], str]:
    """The target's box in the goal image: the operator's, else the detector's for the kind (`GoalError`
    when it finds none)."""
    if config.goal_box_px is not None:  # checked inside the camera's image before anything flew
        return box_from_xywh(config.goal_box_px), "given"
    detector = shipped_detector()
    detections = [d for d in detector.detect_all(image) if d.kind == config.kind]
    if not detections:
        raise GoalError(f"the detector (it knows {', '.join(detector.config.kinds)}) found no {config.kind}")
    best = max(detections, key=lambda d: d.confidence)
    return tuple(float(v) for v in best.bbox_px), "detector"  # type: ignore[return-value]


@functools.cache
def shipped_detector() -> Any:
    """The shipped image detector, loaded once. Load it on the ground (`collect_flown` does, when the goal
    box is the detector's): torch's import and the ONNX export hold Python's lock for seconds, during which
    MAVSDK's callback thread waits and its setpoint stream with it, and PX4 (and the sim-vehicle) fail safe
    out of offboard."""
    from perception.image_detector import ImageDetector  # torch: loaded only when the detector is asked

    return ImageDetector.shipped()


def record_goal(
    vehicle: Vehicle, camera: Camera, model: CameraModel, config: FlownCollectConfig
) -> GoalRecord:
    """Settle, then the goal pose, image, box and distance (`GoalError` naming what is missing)."""
    settled, _ = wait_settled(vehicle, config.settling)
    if not settled:
        log.warning("not settled at the goal within %.0f s: recording it as it is", config.settling.timeout_s)
    pose, range_m = sample_goal_pose(vehicle)
    frame = read_fresh(camera, time.monotonic(), config.frame_lag_s, FRAME_WAIT_S)
    if (frame.width, frame.height) != (model.width, model.height):
        raise GoalError(
            f"the camera sends {frame.width}x{frame.height} px images, the camera model says "
            f"{model.width}x{model.height}: fix the camera file"
        )
    if config.distance_m is not None:
        depth, source = config.distance_m, "given"
    elif range_m is not None:
        depth, source = range_m, "rangefinder"
    else:
        raise GoalError(
            "no forward rangefinder reading at the goal pose (DISTANCE_SENSOR, orientation forward): give "
            "the target's distance with --distance-m"
        )
    for attempt in range(1, DETECTOR_FRAMES + 1):
        try:
            box, box_source = goal_box(config, frame.image)
            break
        except GoalError as exc:
            if attempt == DETECTOR_FRAMES:
                candidate = GoalRecord(
                    pose, None, depth, source, "none", config.kind, (frame.width, frame.height), frame.image
                )
                path = save_goal(candidate, model, config.out_dir, CANDIDATE)
                raise GoalError(
                    f"{exc} in the goal image: it is saved as a goal candidate, {path.with_suffix('.png')}; "
                    f"read the target's box off it and fly from it: --goal {path} --goal-box x,y,w,h"
                ) from None
            log.info("no %s detected in the goal frame: trying the next frame", config.kind)
            frame = read_fresh(camera, time.monotonic(), config.frame_lag_s, FRAME_WAIT_S)
    goal = GoalRecord(
        pose, box, depth, source, box_source, config.kind, (frame.width, frame.height), frame.image
    )
    log.info(
        "goal: %s, target box %s (%s), %.2f m (%s)",
        pose,
        [round(v, 1) for v in box],
        box_source,
        depth,
        source,
    )
    return goal


def centre_by_image(
    vehicle: Vehicle, camera: Camera, model: CameraModel, config: FlownCollectConfig, control: PoseControl
) -> None:
    """`--goal scene`: a few small moves that bring the detected target to the image centre, as an
    operator watching the stream would (the pose geometry turns a pixel offset into metres)."""
    epsilon = config.epsilon_px or model.width * 10.0 / 224.0
    for _ in range(CENTRING_MOVES):
        goal = record_goal(vehicle, camera, model, config)
        du, dv = goal.offset_px
        if abs(du) <= 0.3 * epsilon and abs(dv) <= 0.3 * epsilon:
            return
        here = goal.pose
        target = model.point_ned(here, (du, dv), goal.depth_m)
        centred = model.pose_for_offset(target, (0.0, 0.0), goal.depth_m, here.yaw_deg)
        log.info("centring the target by the image: offset (%.1f, %.1f) px", du, dv)
        fly_to(vehicle, centred, control, config.settling)
    log.warning(
        "the target is not centred within 0.3 ε after %d moves: the goal is where it is", CENTRING_MOVES
    )


def verify_goal(
    vehicle: Vehicle,
    camera: Camera,
    model: CameraModel,
    goal: GoalRecord,
    agree_px: float,
    lag_s: float = 0.0,
) -> tuple[float, float]:
    """At the goal pose of an earlier flight: the target must be where the goal image had it. Returns the
    tracked offset (`GoalError` when it is not found, or too far from the goal image's)."""
    assert goal.image is not None
    frame = read_fresh(camera, time.monotonic(), lag_s, FRAME_WAIT_S)
    tracker = TemplateTracker(goal.image, goal.box_px)
    du0, dv0 = goal.offset_px
    width, height = model.width, model.height
    found = tracker.track(frame.image, (du0 + width / 2, dv0 + height / 2), 3.0 * agree_px, 1.0)
    tolerance = 2.0 * agree_px  # the pose estimate may have drifted since: a moved frame is a larger jump
    if found is None:
        raise GoalError(
            "at the goal pose the camera does not see the goal image's target: the vehicle's local frame "
            "has moved (another takeoff spot, a reset estimator?); record a new goal"
        )
    du, dv = found.centre_px[0] - width / 2, found.centre_px[1] - height / 2
    if math.hypot(du - du0, dv - dv0) > tolerance:
        raise GoalError(
            f"at the goal pose the target is at ({du:.1f}, {dv:.1f}) px, the goal image had it at "
            f"({du0:.1f}, {dv0:.1f}): the vehicle's local frame has moved; record a new goal"
        )
    return du, dv


def centre_goal(
    vehicle: Vehicle,
    camera: Camera,
    model: CameraModel,
    goal: GoalRecord,
    config: FlownCollectConfig,
    control: PoseControl,
) -> GoalRecord:
    """A goal file flown to again (a goal candidate with the operator's box, or an earlier collection's
    goal), recorded again here: that frame and the goal image's box tracked in it. Where the target lies
    more than ε/2 from the image centre (PX4's `--goal scene` left it 39 px off), a few small moves bring
    it nearer first, the offset turned into metres by the pose geometry, as `centre_by_image` does with the
    detector (ε/2: finer than that the pose flight's 5 cm tolerance does not move). The goal images must
    show the target centred: they are the planner's goal, and the centre class of the detector's sectors."""
    assert goal.image is not None and goal.box_px is not None
    half_epsilon = 0.5 * (config.epsilon_px or model.width * 10.0 / 224.0)
    tracker = TemplateTracker(goal.image, goal.box_px)

    def seen_here() -> tuple[PoseNed, Frame, tuple[float, float, float, float], float, float]:
        wait_settled(vehicle, config.settling)
        pose, _ = sample_goal_pose(vehicle)
        frame = read_fresh(camera, time.monotonic(), config.frame_lag_s, FRAME_WAIT_S)
        found = tracker.track(frame.image)
        if found is None:
            raise GoalError("at the goal pose the camera does not see the goal image's target")
        du, dv = found.centre_px[0] - model.width / 2.0, found.centre_px[1] - model.height / 2.0
        return pose, frame, found.bbox_px, du, dv

    pose, frame, box, du, dv = seen_here()
    for _ in range(CENTRING_MOVES):
        if abs(du) <= half_epsilon and abs(dv) <= half_epsilon:
            break
        log.info("centring the target by the goal image's box: offset (%.1f, %.1f) px", du, dv)
        target = model.point_ned(pose, (du, dv), goal.depth_m)
        fly_to(vehicle, model.pose_for_offset(target, (0.0, 0.0), goal.depth_m, pose.yaw_deg), control,
               config.settling)  # fmt: skip
        pose, frame, box, du, dv = seen_here()
    if abs(du) > half_epsilon or abs(dv) > half_epsilon:
        log.warning("the target is (%.1f, %.1f) px off centre after %d moves: the goal is here", du, dv,
                    CENTRING_MOVES)  # fmt: skip
    return GoalRecord(pose, box, goal.depth_m, goal.distance_source, goal.box_source, goal.kind,
                      (frame.width, frame.height), frame.image)  # fmt: skip
