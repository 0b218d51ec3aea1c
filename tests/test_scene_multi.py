"""Scenes of several targets: a single-target scene exactly as before, the others beside the
named one (distinct kinds, disjoint footprints, all in view from its centred pose), twins told
apart by their trim colour, and every target's truth from the world."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from drone_inspect_core.vocabulary import colour_name
from sim_world.rendering.camera import CameraConfig
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig, load_scene_config, with_targets
from sim_world.scene.sampling import rects_overlap, sample_scene, target_footprint
from sim_world.world import World, WorldConfig

SCENES_DIR = Path(__file__).resolve().parents[1] / "scenes"

SINGLE_TARGET_SNAPSHOT = {
    "default/0": "97d35482045a2d1a",
    "default/7": "2126f80d4959b924",
    "default/42": "d24dde0dbcdcce46",
    "default/99991": "80cd0e1621e841b9",
    "cluttered/1": "a865561a4dd99694",
    "cluttered/1234": "f0ac71adece8060a",
    "valve/1": "deb5a41c82da585b",
    "valve/99991": "51f8d6db7cdbec85",
}
"""sha256 (first 16 hex digits) of `json.dumps(sample_scene(config, seed).as_dict(), sort_keys=True)`,
computed with the code before scenes held several targets (commit 37ee047), `others` left out.
Regenerate only for a deliberate change of the single-target draw, which also changes every
dataset's images."""


def _digest(config: SceneConfig, seed: int) -> str:
    params = sample_scene(config, seed).as_dict()
    assert params.pop("others") == []
    return hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]


@pytest.mark.parametrize("key", sorted(SINGLE_TARGET_SNAPSHOT))
def test_single_target_scenes_are_drawn_exactly_as_before(key: str) -> None:
    name, seed = key.split("/")
    config = DEFAULT_SCENE if name == "default" else load_scene_config(SCENES_DIR / f"{name}.yaml")
    assert config.target.count == (1, 1)
    assert _digest(config, int(seed)) == SINGLE_TARGET_SNAPSHOT[key]


def test_single_target_scene_keeps_its_full_width_mount() -> None:
    params = sample_scene(with_targets(DEFAULT_SCENE, count=(1, 1)), 1)  # seed 1: a valve
    assert params.others == () and params.targets == (params.target,)
    assert params.target.kind == "valve"
    assert [(m.kind, m.east_m, m.width_m) for m in params.mounts] == [
        ("pipe_h", 0.0, DEFAULT_SCENE.wall.width_m)
    ]


def test_named_target_and_the_rest_of_the_scene_do_not_move_with_the_count() -> None:
    one, three = sample_scene(DEFAULT_SCENE, 11), sample_scene(with_targets(DEFAULT_SCENE, (3, 3)), 11)
    assert three.target == one.target and three.lighting == one.lighting
    assert (three.wall_texture, three.wall_colour, three.camera_noise_std) == (
        one.wall_texture,
        one.wall_colour,
        one.camera_noise_std,
    )
    assert len(three.others) == 2


@pytest.mark.parametrize("seed", [0, 3, 8, 21])
def test_three_targets_distinct_disjoint_and_in_view_from_the_centred_pose(seed: int) -> None:
    scene = with_targets(DEFAULT_SCENE, (3, 3))
    keep = scene.clutter.keep_out_m
    params = sample_scene(scene, seed)
    targets = params.targets
    assert len(targets) == 3 and len({t.kind for t in targets}) == 3
    for i, a in enumerate(targets):
        for b in targets[i + 1 :]:
            assert not rects_overlap(target_footprint(a, keep), target_footprint(b)), (a.kind, b.kind)
    # Every target gets a local mount that crosses no other target's face.
    assert all(m.width_m <= 1.4 + 1e-9 for m in params.mounts if m.kind == "pipe_h")
    for mount in params.mounts:
        crossed = [t.kind for t in targets if rects_overlap(mount.footprint(), target_footprint(t))]
        assert len(crossed) <= 1, (mount, crossed)  # at most its own target
    # Nothing else on the wall enters any target's keep-out.
    for item in (*params.clutter, *params.distractors):
        assert not any(rects_overlap(item.footprint(), target_footprint(t, keep)) for t in targets), item

    with World(WorldConfig(scene=scene, camera=CameraConfig(width=96, height=96)), seed) as world:
        assert world.scene.sampled == params
        assert [t.kind for t in world.scene.targets] == [t.kind for t in targets]
        assert world.scene.named_index == 0 and world.scene.target_kind == targets[0].kind
        assert world.scene.target_attribute == colour_name(targets[0].bezel_colour)
        body_ids = [t.body_id for t in world.scene.targets]
        assert body_ids[0] == world.scene.target_body_id and len(set(body_ids)) == 3
        assert set(body_ids) <= set(world.scene.body_ids())
        position, yaw = world.scene.pose_for_offset(0.0, 0.0, 2.5, 0.0)
        world.teleport(position, yaw)
        render = world.render()
        truths = world.targets_truth(render)
        assert truths[0] == world.target_truth(render)
        assert abs(truths[0].offset_px[0]) < 2.0  # centred on the named target
        for target, truth in zip(world.scene.targets, truths, strict=True):
            assert truth.in_view and truth.fully_in_view, (seed, target.kind, truth.centre_px)
            assert truth.mask_px and truth.mask_px > 0, (seed, target.kind)  # seen in the render


@pytest.mark.parametrize("seed", range(6))
def test_twins_share_the_named_kind_and_differ_in_attribute(seed: int) -> None:
    params = sample_scene(load_scene_config(SCENES_DIR / "twins.yaml"), seed)
    named, twin = params.target, params.others[0]
    assert twin.kind == named.kind
    assert colour_name(twin.bezel_colour) != colour_name(named.bezel_colour)
    assert 2 <= len(params.targets) <= 3


def test_one_kind_only_still_tells_targets_apart_by_colour() -> None:
    target = DEFAULT_SCENE.target.model_copy(update={"kinds": ("valve",), "other_kinds": ("valve",)})
    scene = with_targets(DEFAULT_SCENE.model_copy(update={"target": target}), (4, 4))
    for seed in range(5):
        targets = sample_scene(scene, seed).targets
        assert {t.kind for t in targets} == {"valve"}
        assert len({colour_name(t.bezel_colour) for t in targets}) == 4


def test_the_multi_target_scene_files() -> None:
    multi = load_scene_config(SCENES_DIR / "multi.yaml")
    assert multi.target.count == (2, 4) and not multi.target.twins
    assert multi.model_copy(update={"target": DEFAULT_SCENE.target}) == DEFAULT_SCENE
    held = load_scene_config(SCENES_DIR / "heldout_look.yaml")
    assert not set(held.wall.colours) & set(DEFAULT_SCENE.wall.colours)
    assert not set(held.floor.colours) & set(DEFAULT_SCENE.floor.colours)
    assert held.lighting.azimuth_deg[1] < DEFAULT_SCENE.lighting.azimuth_deg[0]
    assert held.lighting.ambient[1] <= DEFAULT_SCENE.lighting.ambient[0]
    # What instructions name stays the training palette.
    assert held.target.bezel_colours == DEFAULT_SCENE.target.bezel_colours
    assert held.target.kinds == DEFAULT_SCENE.target.kinds
