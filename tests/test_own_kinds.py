"""A kind of one's own, end to end in the rendered world: a scene file adds it, the world draws its
picture where the truth says, a mission names it, a collection records it, the gym env serves it."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from own_kinds import MUG, MUG_PHOTO

from controller.missions.schema import MissionFileError, parse_mission
from controller.missions.setup import scene_config_for
from drone_inspect_core.dataset import load_manifest
from sim_world.collection.collect import CollectConfig, collect
from sim_world.rendering.camera import CameraConfig
from sim_world.scene.config import SceneConfigError, load_scene_config
from sim_world.world import World, WorldConfig


@pytest.fixture
def mug_scene(tmp_path: Path) -> Path:
    """A scene file beside its picture, as a user keeps them: the image path relative to the file."""
    shutil.copy(MUG_PHOTO, tmp_path / "mug.png")
    scene = tmp_path / "mug.yaml"
    kind = {**MUG, "image": "mug.png"}
    scene.write_text(yaml.safe_dump({"kinds": {"mug": kind}, "target": {"kinds": ["mug"], "count": [2, 2]}}))
    return scene


def test_the_world_draws_the_picture_where_the_truth_puts_it(mug_scene: Path) -> None:
    config = load_scene_config(mug_scene)
    assert config.kinds["mug"]["face"]["image"] == str(mug_scene.parent / "mug.png")
    camera = CameraConfig(width=224, height=224)
    with World(WorldConfig(scene=config, camera=camera), seed=3) as world:
        scene = world.scene
        assert scene.targets[0].kind == "mug" and scene.targets[0].attribute is None
        assert scene.targets[1].kind != "mug" and scene.targets[1].attribute is not None
        position, yaw = scene.pose_for_offset(0.15, -0.1, 1.6, 4.0)
        world.teleport(position, yaw)
        render = world.render()
        truth = world.target_truth(render)
        assert truth.in_view and truth.fully_in_view
        mask = render.seg == scene.target_body_id
        rows, cols = np.nonzero(mask)
        assert mask.sum() > 400  # the picture's panel, not a speck
        # The panel's pixels sit where the projected outline says: box edges within 2 px.
        u0, v0, u1, v1 = truth.bbox_px
        assert abs(cols.min() - u0) <= 2 and abs(cols.max() + 1 - u1) <= 2
        assert abs(rows.min() - v0) <= 2 and abs(rows.max() + 1 - v1) <= 2
        # Its picture is drawn on it: the face is far from one flat colour.
        assert render.rgb[mask].std(axis=0).mean() > 20


def test_a_scene_names_its_own_kinds_and_a_bad_picture_is_named(tmp_path: Path, mug_scene: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"kinds": {"mug": {**MUG, "image": "nope.png"}}}))
    with pytest.raises(SceneConfigError, match=r"bad.yaml: kinds: mug.face.image: no such file"):
        load_scene_config(bad)
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text(yaml.safe_dump({"target": {"kinds": ["mug"]}}))
    with pytest.raises(SceneConfigError, match=r"target.kinds\[0\]: unknown target kind 'mug'"):
        load_scene_config(unknown)


def test_a_mission_adds_a_kind_and_names_it(tmp_path: Path) -> None:
    mission = parse_mission({"name": "mug", "kinds": {"mug": MUG}, "target_kind": "mug", "targets": 2})
    assert mission.vocabulary.kind("mug").noun == "mug"
    config = scene_config_for(mission)
    assert config.target.kinds == ("mug",) and "mug" in config.vocabulary.kind_names
    with pytest.raises(MissionFileError, match="target_kind: unknown target kind 'flange'"):
        parse_mission({"name": "x", "target_kind": "flange"})
    with pytest.raises(MissionFileError, match=r"kinds: mug\.face\.size_m"):
        parse_mission({"name": "x", "kinds": {"mug": {**MUG, "size_m": [0, 1]}}})


def test_a_rendered_collection_records_the_kind_and_no_trim(tmp_path: Path, mug_scene: Path) -> None:
    config = CollectConfig(
        out_dir=tmp_path / "data", seed=1, scene=load_scene_config(mug_scene), scene_file=str(mug_scene),
        n_goal=2, n_per_sector=1, n_test=2, n_empty=1, size_px=96, images_per_scene=4,
    )  # fmt: skip
    collect(config, progress=False)
    rows, meta = load_manifest(tmp_path / "data")
    named = [r for r in rows if r["split"] != "empty"]
    assert named and all(r["target_kind"] == "mug" and r["target_attribute"] is None for r in named)
    assert meta["scene_config"]["kinds"]["mug"]["noun"] == "mug"


def test_the_gym_env_serves_a_kind_of_ones_own(mug_scene: Path) -> None:
    gymnasium = pytest.importorskip("gymnasium")
    from controller.evaluation import gym_env  # registers the env

    env = gymnasium.make(gym_env.ENV_ID, scene=str(mug_scene), kinds=None)
    try:
        _, info = env.reset(seed=0, options={"target_kind": "mug"})
        assert info["target_kind"] == "mug" and info["offset_px"] is not None
    finally:
        env.close()
