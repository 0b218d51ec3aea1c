"""The poses a flown collection visits: goal images around the goal pose, the sector pattern, empty views.

Section 4.2 of the paper, as `sim_world.collection.plan` renders it, planned for a vehicle instead: a
sector is where the target lies in the image, cut by the ε bands of the labelling rule (`N` = above the
centre, ...; `centre` = within ε on both axes). Each capture draws the target's pixel offset in its
sector (clear of the ε bands by `band_margin`, the whole face inside the image) and its distance (the
goal's, ± the box's forward half size), and the pose that shows it so is solved with the camera model
from where the goal image put the target. Poses outside the box are drawn again. The heading stays the
goal's: the face moves and scales in the image but does not turn, which is what the tracker follows.

Goal images: small offsets (≤ `goal_radius` · ε) around the goal pose. Empty views: the goal position
turned `empty_yaw_deg` left or right, the target out of the image (the paper's `empty` split).

The order is the flight's: goal images, then the sector and centre captures in a nearest-neighbour
tour from the goal, then the empty views. Captures are grouped in time blocks of `block_size`; every
`test_every`-th block of sector captures is held out (split `test`), so test images come from stretches
of the flight that training never saw (no scene seeds needed). Seeded: the same goal and seed give the
same plan, which is written beside the dataset so that `--resume` flies exactly the captures not taken.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from controller.collection.config import Box3
from drone_inspect_core.centring import SECTOR_DIRECTIONS
from perception.camera_model import CameraModel, PoseNed

CLASSES = ("centre", *SECTOR_DIRECTIONS)


@dataclass(frozen=True)
class GoalGeometry:
    """What the plan needs of the goal: its pose, the target's offset and box in the goal image, its
    distance along the camera's axis."""

    pose: PoseNed
    offset_px: tuple[float, float]
    box_px: tuple[float, float, float, float]
    depth_m: float


@dataclass(frozen=True)
class PlannedCapture:
    """One capture of the plan: where to fly and which class it was drawn for."""

    index: int
    id: str
    kind: str
    """"goal", "sector" (the eight sectors and the centre class) or "empty"."""
    sector: str
    split: str
    block: int
    pose: PoseNed
    wanted_offset_px: tuple[float, float] | None

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "pose": self.pose.as_dict()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PlannedCapture:
        wanted = data["wanted_offset_px"]
        return cls(
            index=int(data["index"]), id=str(data["id"]), kind=str(data["kind"]), sector=str(data["sector"]),
            split=str(data["split"]), block=int(data["block"]), pose=PoseNed(**data["pose"]),
            wanted_offset_px=None if wanted is None else (float(wanted[0]), float(wanted[1])),
        )  # fmt: skip


class PlanError(ValueError):
    """The protocol cannot be planned in this box (the message names the option to change)."""


@dataclass(frozen=True)
class PlanSettings:
    """The plan's sizes and margins (from `FlownCollectConfig`)."""

    n_goal: int
    n_per_sector: int
    n_empty: int
    box: Box3
    epsilon_px: float
    block_size: int
    test_every: int
    empty_yaw_deg: float
    min_altitude_m: float
    seed: int
    goal_radius: float = 0.3
    band_margin: float = 0.3
    """Sector offsets keep this share of ε clear of the ε bands (flying errors move captures)."""
    edge_px: float = 14.0
    """Room between the face (with the tracker's margin) and the image's edge: the template must fit."""


def plan_captures(camera: CameraModel, goal: GoalGeometry, settings: PlanSettings) -> list[PlannedCapture]:
    """The whole plan, in flight order (`PlanError` when a sector cannot be reached inside the box)."""
    rng = np.random.default_rng(np.random.SeedSequence([settings.seed, 0xF10A]))
    target = camera.point_ned(goal.pose, goal.offset_px, goal.depth_m)
    drawn: list[tuple[str, str, PoseNed, tuple[float, float] | None]] = []
    for _ in range(settings.n_goal):
        offset = _goal_offset(rng, settings)
        drawn.append(("goal", "centre", _pose(camera, goal, target, offset, goal.depth_m), offset))
    sectors = [
        (name, *_sector_capture(camera, goal, target, name, rng, settings))
        for name in CLASSES
        for _ in range(settings.n_per_sector)
    ]
    drawn += [("sector", name, pose, offset) for name, pose, offset in _tour(goal.pose, sectors)]
    for k in range(settings.n_empty):
        turn = settings.empty_yaw_deg * (1 if k % 2 == 0 else -1)
        drawn.append(("empty", "none", goal.pose.moved(0.0, 0.0, 0.0, goal.pose.yaw_deg + turn), None))
    plan = []
    for index, (kind, sector, pose, offset) in enumerate(drawn):
        block = index // settings.block_size
        split = {"goal": "goal", "empty": "empty"}.get(kind) or (
            "test" if block % settings.test_every == settings.test_every - 1 else "train"
        )
        plan.append(PlannedCapture(index, f"img_{index:06d}", kind, sector, split, block, pose, offset))
    return plan


def _goal_offset(rng: np.random.Generator, settings: PlanSettings) -> tuple[float, float]:
    radius = settings.goal_radius * settings.epsilon_px * math.sqrt(rng.random())
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return radius * math.cos(angle), radius * math.sin(angle)


def _pose(
    camera: CameraModel, goal: GoalGeometry, target: np.ndarray, offset: tuple[float, float], depth_m: float
) -> PoseNed:
    return camera.pose_for_offset(target, offset, depth_m, goal.pose.yaw_deg)


def _sector_capture(
    camera: CameraModel,
    goal: GoalGeometry,
    target: np.ndarray,
    sector: str,
    rng: np.random.Generator,
    settings: PlanSettings,
) -> tuple[PoseNed, tuple[float, float]]:
    """A pose inside the box that shows the target in `sector`, its face whole in the image."""
    eps, margin = settings.epsilon_px, settings.band_margin * settings.epsilon_px
    sx, sz = SECTOR_DIRECTIONS.get(sector, (0, 0))
    u0, v0, u1, v1 = goal.box_px
    halves = ((u1 - u0) / 2.0, (v1 - v0) / 2.0)
    for _ in range(400):
        depth = goal.depth_m + float(rng.uniform(-0.8, 0.8)) * settings.box.forward_m
        if depth <= 0.3:
            continue
        scale = goal.depth_m / depth
        offset = []
        for sign, half_px, half_image in (
            (sx, halves[0], camera.width / 2.0),
            (-sz, halves[1], camera.height / 2.0),
        ):
            if sign == 0:
                offset.append(float(rng.uniform(-(eps - margin), eps - margin)))
                continue
            lo, hi = eps + margin, half_image - half_px * scale * 1.2 - settings.edge_px
            if hi <= lo:
                break
            offset.append(sign * float(rng.uniform(lo, hi)))
        if len(offset) != 2:
            continue
        pose = _pose(camera, goal, target, (offset[0], offset[1]), depth)
        forward, right, up = pose.relative_to(goal.pose)
        if settings.box.contains(forward, right, up) and -pose.down_m >= settings.min_altitude_m:
            return pose, (offset[0], offset[1])
    raise PlanError(
        f"no pose inside --box-m {settings.box.as_list()} (above --min-altitude-m "
        f"{settings.min_altitude_m:g}) shows the target in sector {sector} at {goal.depth_m:.2f} m: widen "
        "the box, or start nearer the target"
    )


def _tour(
    start: PoseNed, captures: list[tuple[str, PoseNed, tuple[float, float]]]
) -> list[tuple[str, PoseNed, tuple[float, float]]]:
    """The captures in a nearest-neighbour order from `start` (short flights between captures)."""
    left = list(captures)
    order = []
    here = start.position
    while left:
        k = min(range(len(left)), key=lambda i: float(np.linalg.norm(left[i][1].position - here)))
        order.append(left.pop(k))
        here = order[-1][1].position
    return order
