"""The inspection scene: a wall with pipes and clutter, a floor, and the targets (one named, to centre).

`Scene.build(client_id, config, seed)` draws one scene from the config's ranges
(`scene_sampling`), creates its bodies in the given PyBullet client (`scene_objects`)
and returns what the rest of the world needs: the target's body id, centre and outline
(for the truth bounding box), the lighting and camera noise to render with, the
sampled parameters (for the dataset manifest) and `pose_for_offset`, which places the
drone relative to the target.

Geometry: ENU. The wall is the plane y = `wall_north_m`, facing south (−y); the target
is mounted on it and the drone stands south of it looking north (ENU yaw +90°).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from drone_inspect_core.frames import wrap_rad
from drone_inspect_core.vocabulary import colour_name
from sim_world.rendering.camera import Lighting
from sim_world.scene.assets import AssetCache
from sim_world.scene.bodies import BodyBuilder
from sim_world.scene.config import SceneConfig
from sim_world.scene.objects import BuiltTarget, build_floor, build_item, build_target, build_wall
from sim_world.scene.sampling import SceneParams, TargetParams, sample_scene

logger = logging.getLogger(__name__)

LIGHT_DISTANCE_M = 10.0


@dataclass(frozen=True, eq=False)
class SceneTarget:
    """One inspection target as built: what an instruction calls it and where it is."""

    kind: str
    """The kind's name (`drone_inspect_core.vocabulary`): "gauge", "valve", "switchbox", or a scene's own."""
    attribute: str | None
    """The trim colour's name (`drone_inspect_core.vocabulary.colour_name` of its bezel colour): "red",
    "blue", ...; None for a picture face, which has no trim."""
    body_id: int
    """The face only (dial + bezel, handwheel, door): what the segmentation mask counts."""
    centre_enu_m: np.ndarray
    """(3,) centre of the front face."""
    corners_enu_m: np.ndarray
    """(N, 3) ordered loop around the front face."""
    size_m: float
    """Diameter (gauge, valve) or width (switch box) of the front face."""

    @classmethod
    def of(cls, params: TargetParams, built: BuiltTarget, picture: bool = False) -> SceneTarget:
        return cls(
            kind=params.kind,
            attribute=None if picture else colour_name(params.bezel_colour),
            body_id=built.body_id,
            centre_enu_m=built.centre_enu_m,
            corners_enu_m=built.outline_enu_m,
            size_m=params.size_m,
        )


@dataclass(frozen=True, eq=False)
class Scene:
    """One built scene in one PyBullet client (read-only; `remove()` takes its bodies out)."""

    client_id: int
    sampled: SceneParams
    target_kind: str
    target_body_id: int
    target_centre_enu_m: np.ndarray
    """(3,) centre of the target's front face."""
    target_corners_enu_m: np.ndarray
    """(N, 3) ordered loop around the target's front face (rim circle or box outline); its
    projection bounds the target in the image."""
    target_size_m: float
    """Diameter (gauge, valve) or width (switch box) of the target's front face."""
    wall_north_m: float
    lighting: Lighting
    camera_noise_std: float
    """Std of the Gaussian noise to add to rendered images, in 8-bit grey levels."""
    wall_body_id: int
    floor_body_id: int
    mount_body_ids: tuple[int, ...]
    """What holds the target (stem, pipe, conduit): touching or behind it, never in front."""
    clutter_body_ids: tuple[int, ...]
    distractor_body_ids: tuple[int, ...]
    other_body_ids: tuple[int, ...]
    """The floor's collision plane."""
    targets: tuple[SceneTarget, ...]
    """Every target on the wall, the named one (the `target_*` fields) first."""

    @property
    def named_index(self) -> int:
        """Where the named target (the one to centre) is in `targets`."""
        return 0

    @property
    def target_attribute(self) -> str | None:
        """The named target's trim colour name ("red", "blue", ...)."""
        return self.targets[self.named_index].attribute

    @classmethod
    def build(cls, client_id: int, config: SceneConfig, seed: int, asset_dir: Path | None = None) -> Scene:
        """Draw the scene for `seed` from `config` and create its bodies in `client_id`.

        Texture and mesh files are cached in `asset_dir` (default: a per-user temp folder),
        so building many scenes costs little more than creating their bodies.
        """
        params = sample_scene(config, seed)
        assets = AssetCache(asset_dir)
        builder = BodyBuilder(client_id)
        wall = config.wall
        north = wall.north_m
        wall_id = build_wall(builder, assets, params, north, wall.width_m, wall.height_m)
        floor_id, floor_collider_id = build_floor(builder, assets, params, north)
        vocabulary = config.vocabulary
        target = build_target(builder, assets, params.target, north, vocabulary)
        others = tuple(build_target(builder, assets, t, north, vocabulary) for t in params.others)
        mounts = tuple(build_item(builder, assets, item, north) for item in params.mounts)
        clutter = tuple(build_item(builder, assets, item, north) for item in params.clutter)
        distractors = tuple(build_item(builder, assets, item, north) for item in params.distractors)
        light = params.lighting
        lighting = Lighting(
            direction=light.direction_enu(),
            colour=(light.intensity,) * 3,
            distance_m=LIGHT_DISTANCE_M,
            ambient=light.ambient,
            diffuse=light.diffuse,
            specular=light.specular,
            shadow=light.shadow,
        )
        logger.debug(
            "scene %d: %s at (%.2f, %.2f) and %d other target(s), %d clutter, %d distractors",
            seed,
            params.target.kind,
            params.target.east_m,
            params.target.height_m,
            len(others),
            len(clutter),
            len(distractors),
        )
        return cls(
            client_id=client_id,
            sampled=params,
            target_kind=params.target.kind,
            target_body_id=target.body_id,
            target_centre_enu_m=target.centre_enu_m,
            target_corners_enu_m=target.outline_enu_m,
            target_size_m=params.target.size_m,
            wall_north_m=north,
            lighting=lighting,
            camera_noise_std=params.camera_noise_std,
            wall_body_id=wall_id,
            floor_body_id=floor_id,
            mount_body_ids=(*target.mount_body_ids, *(m for o in others for m in o.mount_body_ids), *mounts),
            clutter_body_ids=clutter,
            distractor_body_ids=distractors,
            other_body_ids=(floor_collider_id,),
            targets=tuple(
                SceneTarget.of(t, b, vocabulary.kind(t.kind).face.image is not None)
                for t, b in zip(params.targets, (target, *others), strict=True)
            ),
        )

    def params(self) -> dict:
        """The sampled parameters as a JSON-able dict (for the dataset manifest)."""
        return self.sampled.as_dict()

    def pose_for_offset(
        self, right_m: float, up_m: float, distance_m: float, yaw_deg: float
    ) -> tuple[np.ndarray, float]:
        """A drone pose relative to the centred pose in front of the (named) target.

        Position: `distance_m` in front of the target's face along the wall normal
        (south), shifted `right_m` east and `up_m` up. Heading: facing the wall (ENU yaw
        +90°) turned by `yaw_deg`, positive clockwise seen from above (towards east), as
        NED yaw. Returns (position_enu_m (3,), yaw_enu_rad).
        """
        centre = self.target_centre_enu_m
        position = np.array([centre[0] + right_m, centre[1] - distance_m, centre[2] + up_m], dtype=float)
        return position, wrap_rad(math.pi / 2 - math.radians(yaw_deg))

    def body_ids(self) -> tuple[int, ...]:
        """Every body the scene created."""
        return (
            self.wall_body_id,
            self.floor_body_id,
            *(t.body_id for t in self.targets),
            *self.mount_body_ids,
            *self.clutter_body_ids,
            *self.distractor_body_ids,
            *self.other_body_ids,
        )

    def remove(self) -> None:
        """Take the scene's bodies out of the client (textures stay loaded until a reset)."""
        for body in self.body_ids():
            p.removeBody(body, physicsClientId=self.client_id)
