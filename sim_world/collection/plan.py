"""What to collect: the image plan of the paper's protocol and the pose of each image.

Section 4.2 of the paper: goal images with the target centred, and initial states
in eight sectors around it (N, NE, E, …) at random offsets, depths and yaws. Here a
sector is where the target lies in the *image* relative to the image centre, cut by
the same ε bands as the labelling rule, so each sector is exactly one action label:
`N` = target above centre (|du| ≤ ε, dv < −ε: the drone should move up), `NE` =
above and right (du > ε, dv < −ε), `E` = right (du > ε, |dv| ≤ ε), and so on;
`centre` = |du|, |dv| ≤ ε. Each image's pose comes from its own random stream,
`(seed, index)`, so the dataset does not depend on how many workers render it.

A pose is chosen in the image, then solved for: pick the target's pixel offset,
its depth along the optical axis and the drone's yaw, and place the (level) camera
so that the target centre projects exactly there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drone_inspect_core.centring import SECTOR_DIRECTIONS, default_epsilon_px, sector_of_offset
from sim_world.physics.quadrotor import RigidBodyState
from sim_world.rendering.camera import CameraConfig, ForwardCamera, Intrinsics
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.world import FACING_WALL_YAW_ENU_RAD

SECTORS = tuple(SECTOR_DIRECTIONS)  # the ε rule's sectors (drone_inspect_core.centring), written once
__all__ = ["SECTORS", "SECTOR_DIRECTIONS", "sector_of_offset"]  # re-exported: the collection's vocabulary


@dataclass(frozen=True)
class CollectConfig:
    """The collection protocol's sizes and ranges (defaults: the paper's dataset)."""

    out_dir: Path
    seed: int = 0
    scene: SceneConfig = DEFAULT_SCENE
    scene_file: str | None = None
    n_goal: int = 100
    n_per_sector: int = 200
    n_test: int = 400
    n_empty: int = 100
    size_px: int = 224
    hfov_deg: float = 60.0
    epsilon_px: float | None = None
    """None: the default ε for `size_px`."""
    workers: int = 1
    images_per_scene: int = 5
    """A new scene every this many images: many scenes (340 for the paper sizes) generalise far better."""
    distance_m: tuple[float, float] = (1.2, 3.5)
    """Depth of the target centre along the optical axis."""
    yaw_deg: float = 15.0
    """Yaw drawn from ±yaw_deg about facing the wall."""
    edge_fraction: float = 0.15
    """Share of sector images whose target crosses the image border (centre still inside)."""
    altitude_m: tuple[float, float] = (0.4, 3.6)
    """Allowed drone altitude (above the floor, below the top of a 4 m wall)."""
    camera: CameraConfig = field(init=False)

    def __post_init__(self) -> None:
        counts = {
            "n_goal": self.n_goal,
            "n_per_sector": self.n_per_sector,
            "n_test": self.n_test,
            "n_empty": self.n_empty,
        }
        for name, value in counts.items():
            if value < 0:
                raise ValueError(f"{name} must be >= 0, got {value}")
        if self.n_goal + self.n_per_sector == 0:
            raise ValueError("nothing to collect for training: n_goal and n_per_sector are both 0")
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        if self.images_per_scene < 1:
            raise ValueError(f"images_per_scene must be >= 1, got {self.images_per_scene}")
        if not 0.3 < self.distance_m[0] <= self.distance_m[1]:
            raise ValueError(f"distance_m must be an interval above 0.3 m, got {self.distance_m}")
        object.__setattr__(
            self, "camera", CameraConfig(width=self.size_px, height=self.size_px, hfov_deg=self.hfov_deg)
        )
        if self.epsilon_px is None:
            object.__setattr__(self, "epsilon_px", default_epsilon_px(self.size_px))
        if not 0.0 < self.epsilon < self.size_px / 4:
            raise ValueError(f"epsilon_px must be in (0, {self.size_px / 4}), got {self.epsilon_px}")

    @property
    def epsilon(self) -> float:
        return float(self.epsilon_px)  # type: ignore[arg-type]


@dataclass(frozen=True)
class ImageSpec:
    """One planned image: its place in the dataset and the scene it is taken in."""

    index: int
    image_id: str
    split: str
    sector: str
    scene_seed: int


@dataclass(frozen=True)
class CollectionPlan:
    images: tuple[ImageSpec, ...]
    train_scene_seeds: tuple[int, ...]
    test_scene_seeds: tuple[int, ...]

    def chunks(self) -> list[tuple[ImageSpec, ...]]:
        """Images grouped by scene, in plan order (a worker builds each scene once)."""
        groups: dict[int, list[ImageSpec]] = {}
        for spec in self.images:
            groups.setdefault(spec.scene_seed, []).append(spec)
        return [tuple(g) for g in groups.values()]


def plan_collection(cfg: CollectConfig) -> CollectionPlan:
    """Every image's split, sector and scene; training and test scene seeds are disjoint."""
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0xC011EC7]))
    n_train_images = cfg.n_goal + len(SECTORS) * cfg.n_per_sector
    n_held_out = cfg.n_test + cfg.n_empty
    n_train_scenes = math.ceil(n_train_images / cfg.images_per_scene)
    n_test_scenes = math.ceil(n_held_out / cfg.images_per_scene) if n_held_out else 0
    seeds = rng.choice(2**31 - 1, size=n_train_scenes + n_test_scenes, replace=False).tolist()
    train_seeds, test_seeds = tuple(seeds[:n_train_scenes]), tuple(seeds[n_train_scenes:])
    assert not set(train_seeds) & set(test_seeds), "training and test scene seeds overlap"

    # Goal and sector images mixed over the training scenes, so each scene holds some of each.
    train_kinds = [("goal", "centre")] * cfg.n_goal + [
        ("train", s) for s in SECTORS for _ in range(cfg.n_per_sector)
    ]
    order = rng.permutation(len(train_kinds))
    train_scene_of = {int(k): train_seeds[pos // cfg.images_per_scene] for pos, k in enumerate(order)}
    held_out, held_scene_of = _held_out_kinds(cfg, test_seeds, rng)
    images = _specs(((train_kinds, train_scene_of), (held_out, held_scene_of)))
    return CollectionPlan(images, train_seeds, test_seeds)


def plan_held_out(cfg: CollectConfig, first_scene_seed: int) -> CollectionPlan:
    """Only `cfg.n_test` test and `cfg.n_empty` empty images, on the consecutive scene seeds from
    `first_scene_seed` (a benchmark's own sample; `cfg`'s goal and sector counts are ignored).

    `plan_collection` draws scene seeds below 2**31 - 1, so a `first_scene_seed` at or above
    2**31 gives scenes no dataset `dronectl collect` writes can hold.
    """
    n_scenes = math.ceil((cfg.n_test + cfg.n_empty) / cfg.images_per_scene)
    seeds = tuple(range(first_scene_seed, first_scene_seed + n_scenes))
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0x4E1D07]))
    held_out, scene_of = _held_out_kinds(cfg, seeds, rng)
    return CollectionPlan(_specs(((held_out, scene_of),)), (), seeds)


def _held_out_kinds(
    cfg: CollectConfig, test_seeds: tuple[int, ...], rng: np.random.Generator
) -> tuple[list[tuple[str, str]], dict[int, int]]:
    """Test images cycling over the eight sectors and the centre (every class represented), then
    the empty ones; each image's scene seed, the images shuffled over the scenes."""
    test_classes = ("centre", *SECTORS)
    held_out = [("test", test_classes[i % len(test_classes)]) for i in range(cfg.n_test)]
    held_out += [("empty", "none")] * cfg.n_empty
    held_order = rng.permutation(len(held_out))
    return held_out, {int(k): test_seeds[pos // cfg.images_per_scene] for pos, k in enumerate(held_order)}


def _specs(groups: tuple[tuple[list[tuple[str, str]], dict[int, int]], ...]) -> tuple[ImageSpec, ...]:
    """Number the images of each (split, sector) list in order, with their scene seeds."""
    images: list[ImageSpec] = []
    counters = {"goal": 0, "train": 0, "test": 0, "empty": 0}
    for kinds, scene_of in groups:
        for k, (split, sector) in enumerate(kinds):
            image_id = f"{split}_{counters[split]:06d}"
            counters[split] += 1
            images.append(ImageSpec(len(images), image_id, split, sector, scene_of[k]))
    return tuple(images)


@dataclass(frozen=True)
class View:
    """Where the target should appear: pixel offset, depth along the optical axis, drone yaw."""

    du_px: float
    dv_px: float
    depth_m: float
    yaw_deg: float
    """NED yaw: 0 faces the wall, positive turns right (east)."""


def drone_pose_for_view(
    camera: ForwardCamera, target_centre_enu_m: np.ndarray, view: View
) -> tuple[np.ndarray, float]:
    """The level drone pose (position ENU, ENU yaw) that images the target centre as `view` says."""
    yaw_enu = FACING_WALL_YAW_ENU_RAD - math.radians(view.yaw_deg)
    level = RigidBodyState(
        np.zeros(3),
        np.array([0.0, 0.0, math.sin(yaw_enu / 2), math.cos(yaw_enu / 2)]),
        np.zeros(3),
        np.zeros(3),
    )
    lens_offset, r_world_from_cam = camera.pose(level)  # camera position of a drone at the origin
    k = camera.intrinsics
    ray = np.array([view.du_px / k.fx, view.dv_px / k.fy, 1.0]) * view.depth_m
    position = np.asarray(target_centre_enu_m, dtype=float) - r_world_from_cam @ ray - lens_offset
    return position, yaw_enu


def sample_view(
    spec: ImageSpec, rng: np.random.Generator, cfg: CollectConfig, target_half_m: tuple[float, float]
) -> View:
    """A target placement for a goal/train/test image of `spec.sector` (target at least partly in view).

    `target_half_m` = (half width, half height) of the target's face, to keep it in view.
    """
    eps, half = cfg.epsilon, cfg.size_px / 2.0
    fx = Intrinsics.from_config(cfg.camera).fx
    for _ in range(100):
        depth = float(rng.uniform(*cfg.distance_m))
        yaw = float(rng.uniform(-cfg.yaw_deg, cfg.yaw_deg))
        if spec.sector == "centre":
            radius, angle = 0.9 * eps * math.sqrt(rng.random()), rng.uniform(0.0, 2.0 * math.pi)
            return View(radius * math.cos(angle), radius * math.sin(angle), depth, yaw)
        sx, sz = SECTOR_DIRECTIONS[spec.sector]
        edge = rng.random() < cfg.edge_fraction
        edge_axis = int(rng.integers(2)) if sx and sz else (0 if sx else 1)
        offsets = []
        for axis, (s, half_m) in enumerate(((sx, target_half_m[0]), (-sz, target_half_m[1]))):
            if s == 0:
                offsets.append(float(rng.uniform(-0.95 * eps, 0.95 * eps)))
                continue
            fully_in = half - fx * half_m / depth - 2.0  # largest |offset| keeping the face inside
            lo, hi = eps + 0.5, fully_in
            if edge and axis == edge_axis:
                lo, hi = max(lo, fully_in), half - 1.0
            if hi <= lo:
                break  # the target is too big at this depth for this sector: draw again
            offsets.append(s * float(rng.uniform(lo, hi)))
        if len(offsets) == 2:
            return View(offsets[0], offsets[1], depth, yaw)
    raise RuntimeError(f"cannot place a target of half size {target_half_m} m in sector {spec.sector}")


def sample_empty_view(
    rng: np.random.Generator,
    cfg: CollectConfig,
    target_half_m: tuple[float, float],
    side_reach_m: tuple[float, float] | None = None,
) -> View:
    """A placement with the target beside the image (left or right), so the camera sees only the wall.

    `side_reach_m` = (west, east): how far the faces of all targets reach from the named target's
    centre, in a scene of several; the named target then stands beside the image far enough that
    the ones on the camera's side are out of it too. None: one target, `max(target_half_m)` each way.
    """
    fx = Intrinsics.from_config(cfg.camera).fx
    half = cfg.size_px / 2.0
    depth = float(rng.uniform(*cfg.distance_m))
    side = float(rng.choice([-1.0, 1.0]))
    # The target right of the image (side > 0) puts the camera west of it: the west reach counts.
    reach = max(target_half_m) if side_reach_m is None else side_reach_m[0 if side > 0 else 1]
    outside = half + fx * reach / depth + 8.0
    du = side * float(rng.uniform(outside, outside + half))
    dv = float(rng.uniform(-half / 2.0, half / 2.0))
    return View(du, dv, depth, float(rng.uniform(-cfg.yaw_deg, cfg.yaw_deg)))
